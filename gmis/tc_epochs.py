"""GNSS epoch preparation for the tightly coupled GMIKF: rover − base single differences
with the satellite states each receiver saw (001 §4.1.3.2 ii, eq. 5.1.7).

For every rover epoch inside the IMU span with a base epoch within the time tolerance
(gnss.epoch_matching), the satellites with C1 at both receivers form a TcEpoch: satellite
positions/velocities at the rover's transmit time (from the pseudorange, so receiver clock
offsets do not bias them; Sagnac-rotated), the base ranges/range rates and elevations at
the known base, and the single differences rover − base of code and phase (m) and
Doppler range rate (m/s). The DD against the filter's reference satellite are formed in
gmis.tc_filter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gmis.errors import GmisInputError
from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.cycle_slips import SlipConfig
from gnss.double_difference import geodetic_up
from gnss.ephemeris import satellite_states_at_reception
from gnss.epoch_matching import DEFAULT_TOLERANCE_S, nearest_epoch
from gnss.rtk import receiver_slip_flags
from gnss.spp import filled_positions, solve_spp_session
from gnss.troposphere import slant_hydrostatic_delay


@dataclass
class TcEpoch:
    """One GNSS epoch prepared for the filter (times on the dataset's time base)."""
    t: float
    prn: np.ndarray              # (n_s,)
    sat_pos: np.ndarray          # (n_s, 3) ECEF at the rover's transmit time, m
    sat_vel: np.ndarray          # (n_s, 3) m/s
    base_range: np.ndarray       # (n_s,) m
    base_rate: np.ndarray        # (n_s,) m/s
    elevation_base: np.ndarray   # (n_s,) rad
    sd: dict                     # "code","l1","l2" (m), "doppler" (m/s): rover − base
    slip: np.ndarray             # (n_s,) bool
    base_troposphere: np.ndarray | None = None  # (n_s,) base hydrostatic slant delay, m


def prepare_tc_epochs(rover, base, nav, base_ecef, time_offset_s: float,
                      t_span=(-np.inf, np.inf), slip_config=None,
                      time_tolerance_s: float = DEFAULT_TOLERANCE_S,
                      hydrostatic_troposphere: bool = False, rover_spp=None):
    """TcEpochs from rover/base observations (gnss.rinex.ObsData) and a broadcast nav.

    time_offset_s: subtracted from the RINEX absolute GPS time to reach the dataset's time
    base (week·604800 when the other files carry seconds of week). Satellite states come
    from the pseudorange-derived transmit times (so receiver clock offsets do not bias
    them), rotated for the Sagnac effect; the rover's approximate position for that is its
    single-point solution (rover_spp, a gnss.spp.SppSession of the rover; solved here
    when None). Slip flags: LLI, gaps, geometry-free and Melbourne-Wübbena on each
    receiver (gnss.rtk.receiver_slip_flags).

    hydrostatic_troposphere: store the base's modelled hydrostatic slant delays
    (gnss.troposphere.saastamoinen_delay with humidity 0, 1/cos z mapping) so the filter
    models the rover − base delay with the rover side at its current antenna position
    (TcFilter._troposphere_dd), as RTKLIB's relative mode does; it matters when the
    antennas' heights differ (≈0.3 mm per metre of height difference at the zenith, ×3.9 at
    15° elevation). Evaluating the rover side at the single-point position instead adds its
    metre-level height noise to the DD phases. Default off: the troposphere cancels."""
    base_ecef = np.asarray(base_ecef, float)
    t_ds = rover.t_gps - time_offset_s
    keep_ep = np.flatnonzero((t_ds >= t_span[0]) & (t_ds <= t_span[1]))
    if keep_ep.size == 0:
        raise GmisInputError(
            f"no rover epoch inside the IMU time span {t_span[0]:.3f}..{t_span[1]:.3f} s "
            f"(rover file spans {t_ds[0]:.3f}..{t_ds[-1]:.3f} s after removing "
            f"{time_offset_s:.0f} s); do the files share a time base?", source=rover.path)
    spp = rover_spp if rover_spp is not None else solve_spp_session(rover, nav)
    if not spp.ok.any():
        raise GmisInputError("no rover epoch has a single-point solution", source=rover.path)
    approx = filled_positions(spp)
    cfg = slip_config or SlipConfig()
    slip_r = receiver_slip_flags(rover, cfg)
    slip_b = receiver_slip_flags(base, cfg)
    jb = nearest_epoch(base.t_gps, rover.t_gps)
    epochs = []
    # slip flags of epochs (or satellites) that form no TcEpoch are carried to the
    # satellite's next TcEpoch: a slip must reset its ambiguity and break its TDCP
    pend_r = np.zeros(rover.prn.size, bool)
    pend_b = np.zeros(base.prn.size, bool)
    b_last = jb[keep_ep[0]] - 1
    for i in keep_ep:
        b = jb[i]
        pend_r |= slip_r[i]
        if abs(base.t_gps[b] - rover.t_gps[i]) > time_tolerance_s:
            continue
        if b > b_last:
            pend_b |= slip_b[b_last + 1:b + 1].any(axis=0)
            b_last = b
        ep = _single_difference_epoch(rover, base, nav, base_ecef, i, b, approx[i],
                                      t_ds[i], hydrostatic_troposphere)
        if ep is None:
            continue
        ep_obj, sr, sb = ep
        ep_obj.slip = pend_r[sr] | pend_b[sb]
        epochs.append(ep_obj)
        pend_r[sr] = False
        pend_b[sb] = False
    return epochs


def _single_difference_epoch(rover, base, nav, base_ecef, i, b, rover_approx, t_ds,
                             hydrostatic_troposphere):
    """(TcEpoch without slip flags, rover columns, base columns) of rover epoch i and base
    epoch b, or None with fewer than two satellites with C1 at both and ephemerides."""
    cols = []
    for s, prn in enumerate(rover.prn):
        cb = base.sat_index(prn)
        if cb >= 0 and np.isfinite(rover.C1[i, s]) and np.isfinite(base.C1[b, cb]):
            cols.append((s, cb, prn))
    if len(cols) < 2:
        return None
    sr = np.array([c[0] for c in cols])
    sb = np.array([c[1] for c in cols])
    prn = np.array([c[2] for c in cols])
    st_r, _, _ = satellite_states_at_reception(nav, prn, np.full(prn.size, rover.t_gps[i]),
                                               rover.C1[i, sr], rover_approx)
    st_b, _, _ = satellite_states_at_reception(nav, prn, np.full(prn.size, base.t_gps[b]),
                                               base.C1[b, sb], base_ecef)
    los_b = st_b.position - base_ecef
    rng_b = np.linalg.norm(los_b, axis=1)
    e_b = los_b / rng_b[:, None]
    up_b = geodetic_up(base_ecef)
    sd = {
        "code": rover.C1[i, sr] - base.C1[b, sb],
        "l1": WAVELENGTH_L1 * (rover.L1[i, sr] - base.L1[b, sb]),
        "l2": WAVELENGTH_L2 * (rover.L2[i, sr] - base.L2[b, sb]),
        "doppler": -WAVELENGTH_L1 * (rover.D1[i, sr] - base.D1[b, sb]),
    }
    base_trop = slant_hydrostatic_delay(base_ecef, st_b.position) \
        if hydrostatic_troposphere else None
    valid = np.all(np.isfinite(st_r.position), axis=1)
    if valid.sum() < 2:
        return None
    ep = TcEpoch(
        t=float(np.round(t_ds, 6)), prn=prn[valid],
        sat_pos=st_r.position[valid], sat_vel=st_r.velocity[valid],
        base_range=rng_b[valid],
        base_rate=np.einsum("ij,ij->i", e_b, st_b.velocity)[valid],
        elevation_base=np.arcsin(e_b @ up_b)[valid],
        sd={k: v[valid] for k, v in sd.items()},
        slip=np.zeros(int(valid.sum()), bool),
        base_troposphere=None if base_trop is None else base_trop[valid])
    return ep, sr[valid], sb[valid]
