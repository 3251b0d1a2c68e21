"""Raw GNSS observation simulation: base / rover / heading-antenna code, phase, Doppler, SNR.

For every receiver r, GPS satellite s and epoch (receiver time tag t, absolute GPS seconds,
see gnss.rinex) the observables are built from the broadcast ephemeris (IS-GPS-200
Table 20-IV through gnss.ephemeris) as (f = 1, 2; γ_1 = 1, γ_2 = (f1/f2)²):

    t_rcv  = t − dt_r(t)                      true reception time (receiver clock dt_r, s)
    τ      : τ = |R3(ω_e τ) r^s(t_rcv − τ) − r_r(t_rcv)| / c   light time with Sagnac
    ρ      = c τ                              geometric range in the ECEF frame of reception
    C_f    = ρ + c (dt_r − dt^s + γ_f T_GD) + T + γ_f I + ε_C          (m)
    L_f    = [ρ + c (dt_r − dt^s) + T − γ_f I] / λ_f + N_f + ε_L / λ_f  (cycles)
    D_f    = −[ρ̇ + c (ḋt_r − ḋt^s)] / λ_f + ε_D / λ_f                  (Hz, RINEX sign)

dt^s is the broadcast satellite clock with the relativistic term (20.3.3.3.3.1) and
(Δt_sv)_L1 = Δt_sv − T_GD, (Δt_sv)_L2 = Δt_sv − γ T_GD for the code (20.3.3.3.3.2). The
phase uses dt^s without T_GD (any constant phase bias is part of the ambiguity). ρ̇ is the
central difference of the light-time solution (±0.5 s; receiver moved with its velocity),
so it includes the Sagnac and light-time terms (error < 1e-4 m/s, set by the ~0.1 µs float
resolution of absolute GPS times).

Noise (001 eq. 5.1.8): white, σ² = σ90² (1 + 1/sin²β) per observable with one σ90 per
observable type (code m, phase m, Doppler m/s; converted to cycles / Hz per frequency).

Atmosphere (short baseline, 001 §5.1.2.2): every receiver gets the SAME slant
troposphere T (Saastamoinen, gnss.troposphere) and L1 ionosphere I (single-layer
mapping at 350 km of a vertical delay ionosphere_zenith_m), evaluated with the elevation
seen from the *atmosphere site* (the first receiver, normally the base), so both cancel
exactly in between-receiver differences. ``differential_atmosphere`` = f adds
f·(own − common) for each receiver (f = 1: each receiver's own elevation; default 0).
The atmosphere rate is not in the Doppler.

Receiver clock (per receiver): drift d_{k+1} = d_k + w_d, w_d ~ N(0, σ_d² Δt); bias
b_{k+1} = b_k + d_k Δt + w_b, w_b ~ N(0, σ_b² Δt); the Doppler uses d_k. Time tags are the
nominal epochs; the antenna truth at the tag is moved back by v·dt_r to the true
reception time (|dt_r| ~ µs by default → µm).

Ambiguities: one random integer per receiver, satellite, frequency and *arc*; an arc ends
when the satellite is not observed (below the mask, blocked, no ephemeris) and the next
arc starts with a new ambiguity and LLI bit 0 set (except arcs starting at the first
epoch). Configured cycle slips add an integer to one frequency's ambiguity from the slip
epoch to the end of the arc and set LLI bit 0 at that epoch on that frequency (unless
CycleSlip.loss_of_lock is False: an undetected slip).

Sky blockages: during [start, end) only satellites whose azimuth is inside one of the
given sectors and/or the ``highest_n`` highest satellites are visible to the *vehicle*
receivers (rover and heading antenna; decided from the first vehicle receiver's
geometry); the base is never blocked.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gmis.earth import ecef_to_enu_matrix, ecef_to_geodetic, frame_rotation, geodetic_to_ecef
from gmis.errors import GmisInputError
from gmis.simulate.validation import ScenarioTable, check_rate, positive
from gnss.constants import (
    C_LIGHT,
    GAMMA_L1_L2,
    GM_GPS,
    OMEGA_EARTH,
    SECONDS_PER_WEEK,
    WAVELENGTH_L1,
    WAVELENGTH_L2,
)
from gnss.ephemeris import ephemeris_matrix, satellite_position_velocity_clock, select_ephemeris
from gnss.rinex import NAV_FIELDS, NavData, gps_seconds_from_datetime64
from gnss.troposphere import saastamoinen_delay

OBSERVABLES = ("C1", "L1", "D1", "S1", "C2", "L2", "D2", "S2")
WAVELENGTH = {1: WAVELENGTH_L1, 2: WAVELENGTH_L2}
GAMMA = {1: 1.0, 2: GAMMA_L1_L2}
IONO_SHELL_HEIGHT_M = 350e3
EARTH_RADIUS_M = 6371e3
RANGE_RATE_STEP_S = 0.5  # absolute GPS s ~1e9 resolve ~0.1 µs: a small step would amplify it
_GPS_EPOCH_NS = np.datetime64("1980-01-06T00:00:00", "ns")
AMBIGUITY_LIMIT = 10 ** 6  # |N| ≤ 1e6 cycles keeps phase in RINEX F14.3


@dataclass
class CycleSlip:
    """A cycle slip of `cycles` (non-zero integer) on frequency 1 or 2 of `prn` at the
    first epoch with t ≥ time_gps (absolute GPS s) in receiver `receiver`. loss_of_lock:
    the receiver sets LLI bit 0 there (False: an undetected slip, no flag)."""
    time_gps: float
    prn: int
    frequency: int
    cycles: int
    receiver: str = "rover"
    loss_of_lock: bool = True


@dataclass
class SkyBlockage:
    """During start_gps ≤ t < end_gps the vehicle receivers only see satellites with
    azimuth in one of azimuth_sectors_deg [(from, to), ...] (clockwise from 'from' to
    'to', degrees; None = all azimuths) and, of those, the highest_n highest (None = all)."""
    start_gps: float
    end_gps: float
    azimuth_sectors_deg: list | None = None
    highest_n: int | None = None


@dataclass
class RawGnssConfig:
    """Simulation settings. σ90 values are the zenith-ish 1σ of 001 eq. 5.1.8."""
    elevation_mask_deg: float = 10.0
    sigma90_code_m: float = 0.3
    sigma90_phase_m: float = 0.003
    sigma90_doppler_m_s: float = 0.03
    ionosphere_zenith_m: float = 3.0
    troposphere: bool = True
    differential_atmosphere: float = 0.0
    clock_bias_sigma_s: float = 1e-7      # initial receiver clock bias 1σ
    clock_drift_sigma_s_s: float = 1e-9   # initial receiver clock drift 1σ
    clock_bias_rw_s_sqrt_s: float = 1e-10
    clock_drift_rw_s_s_sqrt_s: float = 1e-11
    slips: list = field(default_factory=list)
    blockages: list = field(default_factory=list)


@dataclass
class ReceiverTrack:
    """Antenna truth of one receiver at the epoch tags: ecef (n,3) or (3,) m, vel (n,3)
    m/s ECEF (None = static); vehicle = subject to sky blockages."""
    name: str
    ecef: np.ndarray
    vel: np.ndarray | None = None
    vehicle: bool = True


@dataclass
class ReceiverObservations:
    """Simulated observations of one receiver, (n_ep, n_sat) NaN where not observed, in
    the units of gnss.rinex.ObsData (C m, L cycles, D Hz, S dB-Hz), plus the truth:
    ambiguity_l1/l2 (integer cycles of the arc, NaN when not tracked), clock_bias_s,
    clock_drift_s_s (n_ep,), range_m / range_rate_m_s (geometric, at true reception),
    elevation/azimuth (rad), antenna_ecef (n_ep,3) at the tags, noise_* (m, m, m/s)."""
    name: str
    t_gps: np.ndarray
    prn: np.ndarray
    obs: dict
    lli1: np.ndarray
    lli2: np.ndarray
    ambiguity_l1: np.ndarray
    ambiguity_l2: np.ndarray
    clock_bias_s: np.ndarray
    clock_drift_s_s: np.ndarray
    range_m: np.ndarray
    range_rate_m_s: np.ndarray
    elevation: np.ndarray
    azimuth: np.ndarray
    antenna_ecef: np.ndarray
    noise: dict


@dataclass
class RawGnssSimulation:
    """All receivers (dict name → ReceiverObservations, in input order) and the applied
    slips: slip_log rows (receiver index, epoch index, prn, frequency, cycles)."""
    receivers: dict
    prn: np.ndarray
    t_gps: np.ndarray
    slip_log: np.ndarray
    config: RawGnssConfig


# ---------------------------------------------------------------- geometry

def _light_time(nav, eph, idx, prn, t_rcv, r_rcv):
    """Solve τ = |R3(ω_e τ) r^s(t_rcv − τ) − r_rcv| / c (flattened inputs, r_rcv (m,3)).
    Returns (ρ m, satellite position (m,3) in the frame of reception, clock s, drift s/s,
    T_GD s)."""
    tau = np.full(t_rcv.size, 0.075)
    for _ in range(4):
        st = satellite_position_velocity_clock(nav, prn, t_rcv - tau, idx, eph)
        th = OMEGA_EARTH * tau
        c, s = np.cos(th), np.sin(th)
        p = st.position
        rot = np.column_stack([c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1],
                               p[:, 2]])
        tau = np.linalg.norm(rot - r_rcv, axis=1) / C_LIGHT
    return C_LIGHT * tau, rot, st.clock_bias, st.clock_drift, st.tgd


def _elevation_azimuth(r_rcv, sat):
    """Elevation, azimuth (rad, clockwise from north) of sat (n_ep, n_sat, 3) seen from
    r_rcv (n_ep, 3)."""
    el = np.empty(sat.shape[:2])
    az = np.empty(sat.shape[:2])
    for k in range(r_rcv.shape[0]):
        lat, lon, _ = ecef_to_geodetic(r_rcv[k, 0], r_rcv[k, 1], r_rcv[k, 2])
        enu = (sat[k] - r_rcv[k]) @ ecef_to_enu_matrix(lat, lon).T
        horiz = np.hypot(enu[:, 0], enu[:, 1])
        el[k] = np.arctan2(enu[:, 2], horiz)
        az[k] = np.mod(np.arctan2(enu[:, 0], enu[:, 1]), 2.0 * np.pi)
    return el, az


def ionosphere_mapping(elevation):
    """Single-layer (350 km) obliquity 1/√(1 − (R cos β / (R + H))²)."""
    x = EARTH_RADIUS_M * np.cos(elevation) / (EARTH_RADIUS_M + IONO_SHELL_HEIGHT_M)
    return 1.0 / np.sqrt(1.0 - x * x)


def _atmosphere(config, r_rcv, elevation):
    """Slant troposphere T (m) and L1 ionosphere I (m) for (n_ep, n_sat) elevations."""
    el = np.maximum(elevation, np.deg2rad(1.0))
    lat, _, h = ecef_to_geodetic(r_rcv[0, 0], r_rcv[0, 1], r_rcv[0, 2])
    trop = saastamoinen_delay(lat, h, el) if config.troposphere else np.zeros_like(el)
    iono = config.ionosphere_zenith_m * ionosphere_mapping(el)
    return trop, iono


def _clock(n, dt, config, rng):
    """Receiver clock bias (s) and drift (s/s) random walks at n epochs spaced dt (n-1,)."""
    drift = np.empty(n)
    bias = np.empty(n)
    drift[0] = rng.normal(0.0, config.clock_drift_sigma_s_s)
    bias[0] = rng.normal(0.0, config.clock_bias_sigma_s)
    wd = rng.standard_normal(max(n - 1, 0)) * config.clock_drift_rw_s_s_sqrt_s * np.sqrt(dt)
    wb = rng.standard_normal(max(n - 1, 0)) * config.clock_bias_rw_s_sqrt_s * np.sqrt(dt)
    for k in range(n - 1):
        drift[k + 1] = drift[k] + wd[k]
        bias[k + 1] = bias[k] + drift[k] * dt[k] + wb[k]
    return bias, drift


def _in_sector(az_deg, sectors):
    ok = np.zeros(az_deg.shape, dtype=bool)
    for a, b in sectors:
        width = (b - a) % 360.0
        ok |= ((az_deg - a) % 360.0) <= (width if width > 0 else 360.0)
    return ok


def blockage_visibility(t_gps, elevation, azimuth, candidate, blockages):
    """Visibility mask (n_ep, n_sat) of vehicle receivers: candidate (above mask, with
    ephemeris) restricted in every blockage window to the azimuth sectors and the
    highest_n highest satellites."""
    vis = candidate.copy()
    for b in blockages:
        rows = np.flatnonzero((t_gps >= b.start_gps) & (t_gps < b.end_gps))
        for k in rows:
            ok = candidate[k].copy()
            if b.azimuth_sectors_deg is not None:
                ok &= _in_sector(np.rad2deg(azimuth[k]), b.azimuth_sectors_deg)
            if b.highest_n is not None:
                cand = np.flatnonzero(ok)
                keep = cand[np.argsort(-elevation[k, cand])[:b.highest_n]]
                ok[:] = False
                ok[keep] = True
            vis[k] = ok
    return vis


def _arc_starts(tracked):
    """True where an arc begins (tracked now, not tracked at the previous epoch)."""
    start = tracked.copy()
    start[1:] &= ~tracked[:-1]
    return start


def _arc_ambiguities(tracked, rng):
    """Integer ambiguity per arc, broadcast to every epoch of the arc (NaN off-arc)."""
    draws = rng.integers(-AMBIGUITY_LIMIT, AMBIGUITY_LIMIT + 1, size=tracked.shape)
    starts = _arc_starts(tracked)
    amb = np.full(tracked.shape, np.nan)
    for s in range(tracked.shape[1]):
        current = np.nan
        for k in range(tracked.shape[0]):
            if starts[k, s]:
                current = float(draws[k, s])
            if tracked[k, s]:
                amb[k, s] = current
    return amb, starts


# ---------------------------------------------------------------- main entry

def _check_epochs_and_slips(t, receivers, config: RawGnssConfig):
    if t.ndim != 1 or t.size == 0 or np.any(np.diff(t) <= 0):
        raise GmisInputError("epoch times must be a non-empty strictly increasing array",
                             "raw_gnss")
    names = [r.name for r in receivers]
    if len(set(names)) != len(names):
        raise GmisInputError(f"receiver names must be unique, got {names}", "raw_gnss")
    for s in config.slips:
        if s.receiver not in names:
            raise GmisInputError(f"slip receiver {s.receiver!r} is not one of {names}",
                                 "raw_gnss.slip")
        if s.frequency not in (1, 2) or int(s.cycles) != s.cycles or s.cycles == 0:
            raise GmisInputError(f"slip {s}: frequency must be 1 or 2 and cycles a non-zero "
                                 "integer", "raw_gnss.slip")


def _receiver_geometry(r, rng_clk, t, config, nav, eph, idx, prn_grid, n_sat):
    """True ranges, range rates, satellite clocks, elevation/azimuth and the candidate
    (above-mask) satellites of one receiver, with its simulated clock."""
    n_ep = t.size
    pos = np.broadcast_to(np.asarray(r.ecef, float), (n_ep, 3)).copy()
    vel = np.zeros((n_ep, 3)) if r.vel is None else \
        np.broadcast_to(np.asarray(r.vel, float), (n_ep, 3)).copy()
    bias, drift = _clock(n_ep, np.diff(t), config, rng_clk)
    t_rcv = t - bias
    r_true = pos - vel * bias[:, None]
    tr = np.repeat(t_rcv, n_sat)
    rr = np.repeat(r_true, n_sat, axis=0)
    vv = np.repeat(vel, n_sat, axis=0)
    rho, sat, clk, clk_drift, tgd = _light_time(nav, eph, idx, prn_grid, tr, rr)
    h = RANGE_RATE_STEP_S
    rho_p = _light_time(nav, eph, idx, prn_grid, tr + h, rr + vv * h)[0]
    rho_m = _light_time(nav, eph, idx, prn_grid, tr - h, rr - vv * h)[0]
    shape = (n_ep, n_sat)
    sat = sat.reshape(n_ep, n_sat, 3)
    el, az = _elevation_azimuth(r_true, np.where(np.isfinite(sat), sat, 0.0))
    valid = np.isfinite(rho.reshape(shape))
    el = np.where(valid, el, np.nan)
    az = np.where(valid, az, np.nan)
    mask = np.deg2rad(config.elevation_mask_deg)
    return {"pos": pos, "r_true": r_true, "bias": bias, "drift": drift,
            "rho": rho.reshape(shape), "rate": ((rho_p - rho_m) / (2 * h)).reshape(shape),
            "clk": clk.reshape(shape), "clk_drift": clk_drift.reshape(shape),
            "tgd": tgd.reshape(shape), "el": el, "az": az,
            "candidate": valid & (np.nan_to_num(el, nan=-1.0) >= mask)}


def _ambiguities_with_slips(ir, r, tracked, t, prns, config, rng_amb, slip_log):
    """Integer ambiguities and LLI flags per frequency of one receiver's arcs, with the
    configured cycle slips applied (logged into slip_log)."""
    n_ep, n_sat = tracked.shape
    amb, lli = {}, {}
    for f in (1, 2):
        amb[f], starts = _arc_ambiguities(tracked, rng_amb)
        lli[f] = np.zeros((n_ep, n_sat), dtype=np.int8)
        lli[f][1:][starts[1:]] = 1
    for s in config.slips:
        if s.receiver != r.name:
            continue
        k = int(np.searchsorted(t, s.time_gps - 1e-9))
        col = np.flatnonzero(prns == s.prn)
        if k >= n_ep or col.size == 0 or not tracked[k, col[0]]:
            raise GmisInputError(
                f"slip at t={s.time_gps:.3f} PRN {s.prn}: satellite not tracked by "
                f"{r.name} at that epoch", "raw_gnss.slip")
        j = col[0]
        end = k
        while end < n_ep and tracked[end, j]:  # the arc = consecutive tracked epochs
            end += 1
        amb[s.frequency][k:end, j] += s.cycles
        if s.loss_of_lock:
            lli[s.frequency][k, j] |= 1
        slip_log.append((ir, k, s.prn, s.frequency, int(s.cycles)))
    return amb, lli


def _observables(g, tracked, amb, lli, trop, iono, config, rng_noise):
    """Code, phase, Doppler and SNR on L1/L2 of one receiver (module doc models) and the
    noise drawn; untracked satellites are NaN (LLI 0)."""
    n_ep, n_sat = tracked.shape
    sin_el = np.sin(np.where(tracked, g["el"], np.pi / 2))
    sig_scale = np.sqrt(1.0 + 1.0 / (sin_el * sin_el))
    cdt = C_LIGHT * (g["bias"][:, None] - g["clk"])
    cdt_rate = C_LIGHT * (g["drift"][:, None] - g["clk_drift"])
    obs, noise = {}, {}
    for f in (1, 2):
        lam, gam = WAVELENGTH[f], GAMMA[f]
        n_c = rng_noise.standard_normal((n_ep, n_sat)) * config.sigma90_code_m * sig_scale
        n_l = rng_noise.standard_normal((n_ep, n_sat)) * config.sigma90_phase_m * sig_scale
        n_d = rng_noise.standard_normal((n_ep, n_sat)) * config.sigma90_doppler_m_s \
            * sig_scale
        code = g["rho"] + cdt + C_LIGHT * gam * g["tgd"] + trop + gam * iono + n_c
        phase = (g["rho"] + cdt + trop - gam * iono + n_l) / lam + amb[f]
        doppler = -(g["rate"] + cdt_rate + n_d) / lam
        snr = 30.0 + 20.0 * np.sin(np.maximum(g["el"], 0.0)) - (0.0 if f == 1 else 5.0)
        for name, val in ((f"C{f}", code), (f"L{f}", phase), (f"D{f}", doppler),
                          (f"S{f}", snr)):
            obs[name] = np.where(tracked, val, np.nan)
        noise.update({f"C{f}": np.where(tracked, n_c, np.nan),
                      f"L{f}": np.where(tracked, n_l, np.nan),
                      f"D{f}": np.where(tracked, n_d, np.nan)})
        lli[f] = np.where(tracked, lli[f], 0).astype(np.int8)
    return obs, noise


def simulate_raw_gnss(t_gps, receivers, nav: NavData, config: RawGnssConfig | None = None,
                      seed=0, prn=None) -> RawGnssSimulation:
    """Simulate raw GPS observations for receivers (list of ReceiverTrack; the first one is
    the atmosphere site, normally the base) at epoch tags t_gps (absolute GPS s, strictly
    increasing) from broadcast ephemerides nav. seed: int or numpy SeedSequence; prn:
    satellites to consider (default every PRN in nav). Raises GmisInputError for bad
    settings (unknown slip receiver, slip on an untracked satellite, …)."""
    config = config or RawGnssConfig()
    t = np.asarray(t_gps, dtype=float)
    _check_epochs_and_slips(t, receivers, config)
    n_ep = t.size
    prns = np.unique(nav.prn if prn is None else np.asarray(prn)).astype(np.int64)
    n_sat = prns.size
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    rngs = [[np.random.Generator(np.random.PCG64(c)) for c in child.spawn(3)]
            for child in ss.spawn(len(receivers))]
    eph = ephemeris_matrix(nav)
    prn_grid = np.broadcast_to(prns[None, :], (n_ep, n_sat)).ravel()
    idx = select_ephemeris(nav, prn_grid, np.repeat(t, n_sat) - 0.075)
    geo = [_receiver_geometry(r, rng_clk, t, config, nav, eph, idx, prn_grid, n_sat)
           for r, (rng_clk, _, _) in zip(receivers, rngs)]

    vehicle = [i for i, r in enumerate(receivers) if r.vehicle]
    vis_vehicle = None
    if vehicle:
        g0 = geo[vehicle[0]]
        vis_vehicle = blockage_visibility(t, np.nan_to_num(g0["el"], nan=-1.0),
                                          np.nan_to_num(g0["az"]), g0["candidate"],
                                          config.blockages)
    trop_c, iono_c = _atmosphere(config, geo[0]["r_true"], geo[0]["el"])

    out = {}
    slip_log = []
    for ir, (r, g, (_, rng_amb, rng_noise)) in enumerate(zip(receivers, geo, rngs)):
        tracked = g["candidate"] & (vis_vehicle if r.vehicle else True)
        trop, iono = trop_c, iono_c
        if config.differential_atmosphere:
            trop_o, iono_o = _atmosphere(config, g["r_true"], g["el"])
            trop = trop_c + config.differential_atmosphere * (trop_o - trop_c)
            iono = iono_c + config.differential_atmosphere * (iono_o - iono_c)
        amb, lli = _ambiguities_with_slips(ir, r, tracked, t, prns, config, rng_amb, slip_log)
        obs, noise = _observables(g, tracked, amb, lli, trop, iono, config, rng_noise)
        out[r.name] = ReceiverObservations(
            name=r.name, t_gps=t.copy(), prn=prns, obs=obs, lli1=lli[1], lli2=lli[2],
            ambiguity_l1=amb[1], ambiguity_l2=amb[2], clock_bias_s=g["bias"],
            clock_drift_s_s=g["drift"], range_m=np.where(tracked, g["rho"], np.nan),
            range_rate_m_s=np.where(tracked, g["rate"], np.nan), elevation=g["el"],
            azimuth=g["az"], antenna_ecef=g["pos"], noise=noise)
    return RawGnssSimulation(out, prns, t.copy(),
                             np.array(slip_log, dtype=np.int64).reshape(-1, 5), config)


def dd_ambiguity(sim: RawGnssSimulation, base: str, rover: str, frequency: int, epoch: int,
                 prn: int, ref_prn: int) -> float:
    """True DD ambiguity (cycles) ∇ΔN = (N_rover^k − N_base^k) − (N_rover^j − N_base^j)
    (001 eq. 5.1.7 convention) at one epoch."""
    key = f"ambiguity_l{frequency}"
    a, b = getattr(sim.receivers[base], key), getattr(sim.receivers[rover], key)
    k = int(np.flatnonzero(sim.prn == prn)[0])
    j = int(np.flatnonzero(sim.prn == ref_prn)[0])
    return float((b[epoch, k] - a[epoch, k]) - (b[epoch, j] - a[epoch, j]))


def truth_arrays(sim: RawGnssSimulation) -> dict:
    """Flat dict of every truth array for raw_truth.npz (keys '<receiver>_<name>')."""
    out = {"t_gps": sim.t_gps, "prn": sim.prn, "slip_log": sim.slip_log,
           "receivers": np.array(list(sim.receivers))}
    for name, r in sim.receivers.items():
        for key in ("ambiguity_l1", "ambiguity_l2", "clock_bias_s", "clock_drift_s_s",
                    "range_m", "range_rate_m_s", "elevation", "azimuth", "antenna_ecef",
                    "lli1", "lli2"):
            out[f"{name}_{key}"] = getattr(r, key)
        for key, val in r.noise.items():
            out[f"{name}_noise_{key}"] = val
    return out


# ---------------------------------------------------------------- synthetic constellation

def _d19(x: float) -> float:
    """The value as a RINEX D19.12 field holds it (so written files read back exactly)."""
    return float(f"{x:.12E}")


def synthetic_gps_nav(t0_gps: float, hours: float = 24.0, seed: int = 1) -> NavData:
    """A 24-satellite GPS-like Walker 55°: 24/6/1 constellation (PRN 1-24, a = 26 560 km,
    e ≤ 0.01) as broadcast ephemerides every 2 h (4-h fit) from 2 h before t0_gps (absolute
    GPS s) for `hours`. The records of one satellite describe one continuous Keplerian
    orbit (no switch jumps). Clock terms af0 ~ ±100 µs, af1 ~ ±1e-11, T_GD ~ ±10 ns drawn
    from seed. Values are rounded to D19.12 so write_nav_rinex3 round-trips exactly."""
    rng = np.random.default_rng(seed)
    n_planes, per_plane, phasing = 6, 4, 1
    sqrt_a = np.sqrt(26_560e3)
    n_mean = np.sqrt(GM_GPS) / sqrt_a ** 3
    omega_dot = -8.0e-9
    toe_ref = np.floor(t0_gps / 7200.0) * 7200.0 - 7200.0
    toes = toe_ref + 7200.0 * np.arange(int(np.ceil(hours / 2.0)) + 2)
    rows = {k: [] for k in NAV_FIELDS}
    for p in range(n_planes):
        for q in range(per_plane):
            prn = p * per_plane + q + 1
            e = rng.uniform(0.001, 0.01)
            arg_perigee = rng.uniform(-np.pi, np.pi)
            m_ref = 2 * np.pi * q / per_plane + 2 * np.pi * phasing * p / (n_planes * per_plane) \
                - arg_perigee
            node_ref = 2 * np.pi * p / n_planes
            af0, af1, tgd = rng.uniform(-1e-4, 1e-4), rng.uniform(-1e-11, 1e-11), \
                rng.uniform(-1e-8, 1e-8)
            for n_rec, toe in enumerate(toes):
                week = np.floor(toe / SECONDS_PER_WEEK)
                dtoe = toe - toe_ref
                toe_sow_diff = (toe - week * SECONDS_PER_WEEK) - (toe_ref - np.floor(
                    toe_ref / SECONDS_PER_WEEK) * SECONDS_PER_WEEK)
                omega0 = node_ref + (omega_dot - OMEGA_EARTH) * dtoe + OMEGA_EARTH * toe_sow_diff
                m0 = np.mod(m_ref + n_mean * dtoe + np.pi, 2 * np.pi) - np.pi
                rec = {"prn": prn, "toc": toe, "toe": toe, "week": int(week), "sqrt_a": sqrt_a, "e": e,
                           "i0": np.deg2rad(55.0), "omega0": np.mod(omega0 + np.pi, 2 * np.pi) - np.pi,
                           "omega": arg_perigee, "m0": m0, "delta_n": 0.0, "idot": 0.0,
                           "omega_dot": omega_dot, "cuc": 0.0, "cus": 0.0, "crc": 0.0, "crs": 0.0, "cic": 0.0,
                           "cis": 0.0, "af0": af0 + af1 * (toe - toe_ref), "af1": af1, "af2": 0.0,
                           "tgd": tgd, "health": 0.0, "iode": float(n_rec % 256),
                           "iodc": float(n_rec % 256), "fit_interval_h": 4.0}
                for k in NAV_FIELDS:
                    rows[k].append(rec[k])
    arrays = {}
    for k in NAV_FIELDS:
        if k in ("prn", "week"):
            arrays[k] = np.array(rows[k], dtype=np.int64)
        elif k == "toe":
            arrays[k] = np.array(rows[k], dtype=float)
        elif k == "toc":  # through datetime64 as gnss.rinex does, so read-back is exact
            ns = np.array(rows[k], dtype=float).round().astype(np.int64) * 10**9
            arrays[k] = gps_seconds_from_datetime64(_GPS_EPOCH_NS + ns.astype("timedelta64[ns]"))
        else:
            arrays[k] = np.array([_d19(v) for v in rows[k]], dtype=float)
    order = np.lexsort((arrays["toe"], arrays["prn"]))
    return NavData(path="synthetic", version=3.03, **{k: v[order] for k, v in arrays.items()})


def base_ecef_from_llh(lat_rad: float, lon_rad: float, h_m: float) -> np.ndarray:
    """ECEF (m) of a geodetic position."""
    return np.asarray(geodetic_to_ecef(lat_rad, lon_rad, h_m), dtype=float)


# ---------------------------------------------------------------- scenario / dataset glue

def validate_raw_gnss_section(table, sc, source):
    """Normalise the optional scenario section [raw_gnss] (times relative to the start):
    rate_hz = 1, nav = "synthetic" | path, elevation_mask_deg = 10, sigma90_code_m = 0.3,
    sigma90_phase_m = 0.003, sigma90_doppler_m_s = 0.03, ionosphere_zenith_m = 3,
    differential_atmosphere = 0, base_offset_enu_m = [0, 0, 0] (base antenna from the
    origin), [[raw_gnss.slip]] time_s, prn, frequency (1|2), cycles,
    receiver = "rover" | "base" | "heading"; [[raw_gnss.blockage]] start_s, end_s,
    highest_n = 0 (0 = no limit), azimuth_sectors_deg = [] (list of [from, to])."""
    sec = ScenarioTable(table, "[raw_gnss]", source)
    g = {"rate_hz": sec.checked("rate_hz", "float", check_rate, 0.1, 10.0, sc["imu_rate_hz"],
                                default=1.0),
         "nav": sec.get("nav", "str", "synthetic"),
         "elevation_mask_deg": sec.get("elevation_mask_deg", "float", 10.0)}
    for key, default in (("sigma90_code_m", 0.3), ("sigma90_phase_m", 0.003),
                         ("sigma90_doppler_m_s", 0.03), ("ionosphere_zenith_m", 3.0),
                         ("differential_atmosphere", 0.0)):
        g[key] = sec.checked(key, "float", positive, default=default, allow_zero=True)
    if not 0.0 <= g["elevation_mask_deg"] < 60.0:
        sec.fail_key("elevation_mask_deg", f"must be within [0, 60), got {g['elevation_mask_deg']}")
    g["base_offset_enu_m"] = sec.get("base_offset_enu_m", "vec3", [0.0, 0.0, 0.0])
    g["slip"] = []
    for i, item in enumerate(sec.get("slip", "list", [])):
        s = ScenarioTable(item, f"[[raw_gnss.slip]] #{i + 1}", source)
        slip = {"time_s": positive(s, "time_s", s.get("time_s", "float"), allow_zero=True),
                "prn": s.get("prn", "int"), "frequency": s.get("frequency", "int"),
                "cycles": s.get("cycles", "int"),
                "receiver": s.get("receiver", "str", "rover")}
        if slip["frequency"] not in (1, 2):
            s.fail_key("frequency", f"must be 1 or 2, got {slip['frequency']}")
        if slip["cycles"] == 0:
            s.fail_key("cycles", "must be a non-zero integer")
        if slip["receiver"] not in ("rover", "base", "heading"):
            s.fail_key("receiver", f"must be rover, base or heading, got {slip['receiver']!r}")
        s.done()
        g["slip"].append(slip)
    g["blockage"] = []
    for i, item in enumerate(sec.get("blockage", "list", [])):
        b = ScenarioTable(item, f"[[raw_gnss.blockage]] #{i + 1}", source)
        start = positive(b, "start_s", b.get("start_s", "float"), allow_zero=True)
        end = b.get("end_s", "float")
        if end <= start:
            b.fail_key("end_s", f"must be > start_s ({start}), got {end}")
        n = b.get("highest_n", "int", 0)
        if n < 0:
            b.fail_key("highest_n", f"must be >= 0, got {n}")
        sectors = b.get("azimuth_sectors_deg", "list", [])
        if not all(isinstance(p, list) and len(p) == 2 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in p)
                for p in sectors):
            b.fail_key("azimuth_sectors_deg", f"must be a list of [from, to] pairs, got {sectors!r}")
        b.done()
        g["blockage"].append({"start_s": start, "end_s": end, "highest_n": n,
                              "azimuth_sectors_deg": [[float(x) for x in p] for p in sectors]})
    sec.done()
    return g


def simulate_dataset_raw_gnss(scn, traj, frame, seed, out_dir, scenario_dir=None):
    """Simulate [raw_gnss] for a trajectory and write rover.obs, base.obs, heading.obs,
    the nav file and raw_truth.npz into out_dir. Returns (recipe paths dict, recipe [base]
    dict). Epochs fall on IMU samples every imu_rate/rate_hz; the absolute GPS time is
    gps_week·604800 + start_gps_s + t_s."""
    import os

    from gmis.earth import enu_to_ecef
    from gmis.simulate.rinex_writer import copy_nav_file, write_nav_rinex3, write_obs_rinex3
    from gmis.simulate.sensors import antenna_position_velocity, epoch_indices
    from gnss.rinex import read_nav

    cfg_s, sc = scn["raw_gnss"], scn["scenario"]
    t_start = sc["gps_week"] * SECONDS_PER_WEEK + sc["start_gps_s"]
    idx, _ = epoch_indices(traj.t_s, sc["imu_rate_hz"], cfg_s["rate_hz"], [])
    t = t_start + traj.t_s[idx]
    if cfg_s["nav"] == "synthetic":
        nav = synthetic_gps_nav(t[0], hours=(t[-1] - t[0]) / 3600.0 + 4.0)
        nav_name = "synthetic.nav"
    else:
        nav_path = cfg_s["nav"]
        if not os.path.isabs(nav_path) and scenario_dir:
            nav_path = os.path.join(scenario_dir, nav_path)
        nav = read_nav(nav_path)
        nav_name = os.path.basename(nav_path)
        lo, hi = nav.toe.min() - 7200.0, nav.toe.max() + 7200.0
        if t[0] < lo or t[-1] > hi:
            raise GmisInputError(
                f"nav file {nav_path} covers GPS s {lo:.0f}..{hi:.0f} but the scenario runs "
                f"{t[0]:.0f}..{t[-1]:.0f} (set [scenario] gps_week/start_gps_s inside it)",
                "[raw_gnss].nav")
    c_en = frame_rotation(np.asarray(frame, float))  # C_e^n
    to_ecef = np.array([enu_to_ecef(frame, r) for r in np.asarray(cfg_s["base_offset_enu_m"],
                                                                  float)[None, :]])
    base_ecef = to_ecef[0]
    tracks = [ReceiverTrack("base", base_ecef, None, vehicle=False)]
    for name, lever in (("rover", scn["gnss"]["lever_arm_m"]),
                        ("heading", scn["heading"]["lever_arm_m"])):
        pos, vel = antenna_position_velocity(traj.r_enu[idx], traj.v_b[idx],
                                             traj.euler[idx], traj.omega_b[idx],
                                             np.asarray(lever, float))
        ecef = np.array([enu_to_ecef(frame, p) for p in pos])
        tracks.append(ReceiverTrack(name, ecef, vel @ c_en, vehicle=True))
    config = RawGnssConfig(
        elevation_mask_deg=cfg_s["elevation_mask_deg"], sigma90_code_m=cfg_s["sigma90_code_m"],
        sigma90_phase_m=cfg_s["sigma90_phase_m"],
        sigma90_doppler_m_s=cfg_s["sigma90_doppler_m_s"],
        ionosphere_zenith_m=cfg_s["ionosphere_zenith_m"],
        differential_atmosphere=cfg_s["differential_atmosphere"],
        slips=[CycleSlip(t_start + s["time_s"], s["prn"], s["frequency"], s["cycles"],
                         s["receiver"]) for s in cfg_s["slip"]],
        blockages=[SkyBlockage(t_start + b["start_s"], t_start + b["end_s"],
                               b["azimuth_sectors_deg"] or None, b["highest_n"] or None)
                   for b in cfg_s["blockage"]])
    sim = simulate_raw_gnss(t, tracks, nav, config,
                            seed=np.random.SeedSequence([int(seed), 0x52415747]))
    for name, r in sim.receivers.items():
        write_obs_rinex3(os.path.join(out_dir, f"{name}.obs"), r.t_gps, r.prn, r.obs, r.lli1,
                         r.lli2, r.antenna_ecef[0], name.upper(), 1.0 / cfg_s["rate_hz"])
    if cfg_s["nav"] == "synthetic":
        write_nav_rinex3(os.path.join(out_dir, nav_name), nav)
    else:
        copy_nav_file(nav.path, os.path.join(out_dir, nav_name))
    np.savez(os.path.join(out_dir, "raw_truth.npz"), **truth_arrays(sim))
    paths = {"rover_obs": "rover.obs", "base_obs": "base.obs", "heading_obs": "heading.obs",
             "nav": nav_name}
    return paths, {"ecef_m": [float(x) for x in base_ecef]}
