"""GPS broadcast ephemeris: satellite position, velocity and clock (IS-GPS-200, Table 20-IV).

Times are absolute GPS seconds (see gnss.rinex). Conventions:

* Orbit: the broadcast Keplerian elements give the **antenna phase centre** (APC) of the
  satellite in WGS84 ECEF at the GPS time of transmission t (IS-GPS-200 20.3.3.4.3);
  precise SP3 orbits give the centre of mass (offset ≈ 0-2.6 m along the body z axis,
  mostly radial, depending on the block).
* Clock: ``clock_bias`` = a_f0 + a_f1 (t − t_oc) + a_f2 (t − t_oc)² + Δt_r with the
  relativistic correction Δt_r = F e √A sin E_k (20.3.3.3.3.1). It refers to the
  ionosphere-free P1/P2 combination. For L1-only code (C1/P1) the satellite clock is
  (Δt_sv)_L1 = Δt_sv − T_GD (20.3.3.3.3.2); SPP subtracts ``tgd`` itself. T_GD cancels in
  between-receiver differences.
* Selection: the record of the PRN with health == 0 that passes the plausibility screen
  below, whose t_oe is closest to t and |t − t_oe| ≤ fit interval / 2 (4 h fit → ±2 h).
  Ties (equal t_oe, e.g. two uploads in a merged file) go to the first record in file order.
* Plausibility screen (``screen_ephemeris_records``; on by default, ``screen=False``
  disables it everywhere). The health flag alone is not enough: the IGS merged file
  brdc1820.10n carries a health-0 record labelled PRN01 (t_oe 06:00, IODE 90) that is a
  bit-for-bit copy of PRN23's record — a physically perfect orbit of the wrong satellite,
  27 000-41 000 km from PRN01. A record is rejected when

  1. an element is not finite, or the Keplerian elements are not those of a GPS orbit:
     a = √A² outside 26 560 ± 500 km (a slot drift of 1°/day needs only Δa ≈ 25 km; the
     new IIF PRN25 drifting into its slot on 2010-07-01 has +24.5 km), e outside [0, 0.03]
     (IS-GPS-200 Table 20-III range), i_0 outside 40°-70° (GPS planes 55° nominal,
     50.9°-56.9° on that day), or |r| at t_oe and at both fit-window ends outside
     25 000-28 000 km (a(1 ± e) plus harmonic terms of < 1 km);
  2. its clock/ephemeris bookkeeping is inconsistent: IODE ≠ IODC mod 256 (the subframes of
     two data sets, IS-GPS-200 20.3.4.4), t_oe (seconds of week) not a multiple of the
     16 s LSB, or |t_oc − t_oe| larger than half the fit interval;
  3. it disagrees with every other data set of the same PRN (different t_oe or IODE, any
     health — health describes the signal, not the orbit) whose fit window overlaps its
     own, by more than ``NEIGHBOUR_TOLERANCE_M`` = 30 m (maximum position difference at
     the start, middle and end of the overlap). On brdc1820.10n the 517 overlapping pairs
     of genuine records disagree by 0.6 m median, 6.3 m 99th percentile, 7.2 m maximum;
     the copied record by 30 000-41 000 km. 30 m is 4× the largest honest disagreement
     (room for older uploads on other days) and the order of the GPS SPS not-to-exceed
     range error (4.42 × URA). A record with no overlapping neighbour is judged on 1-2
     only; of two records that disagree with nothing else, both are rejected (it cannot
     be told which one is right).

  Limitation: two corrupted records with the same wrong orbit confirm each other.
* Earth rotation during signal travel (Sagnac): the satellite position computed in the ECEF
  frame of the transmission time is rotated about z by ω_e τ into the ECEF frame of the
  reception time, τ = |r_sat − r_rcv| / c (``earth_rotation_correction``).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numba import njit

from gnss.constants import C_LIGHT, F_RELATIVISTIC, GM_GPS, OMEGA_EARTH, SECONDS_PER_WEEK
from gnss.rinex import NavData

# column layout of the packed ephemeris matrix (ephemeris_matrix)
EPH_COLUMNS = ("toc", "toe", "toe_sow", "sqrt_a", "e", "i0", "omega0", "omega", "m0",
               "delta_n", "idot", "omega_dot", "cuc", "cus", "crc", "crs", "cic", "cis",
               "af0", "af1", "af2", "tgd")
(_TOC, _TOE, _TOE_SOW, _SQRTA, _E, _I0, _OMEGA0, _OMEGA, _M0, _DN, _IDOT, _OMEGADOT, _CUC,
 _CUS, _CRC, _CRS, _CIC, _CIS, _AF0, _AF1, _AF2, _TGD) = range(len(EPH_COLUMNS))


@dataclass
class SatelliteStates:
    """Per query: position (n,3) m ECEF, velocity (n,3) m/s ECEF, clock_bias (n,) s
    (with relativistic term, without T_GD), clock_drift (n,) s/s, tgd (n,) s,
    eph_index (n,) record used (−1 none), valid (n,) bool. Invalid rows are NaN."""

    position: np.ndarray
    velocity: np.ndarray
    clock_bias: np.ndarray
    clock_drift: np.ndarray
    tgd: np.ndarray
    eph_index: np.ndarray
    valid: np.ndarray


def ephemeris_matrix(nav: NavData) -> np.ndarray:
    """Pack a NavData into an (n_records, len(EPH_COLUMNS)) float64 matrix for numba."""
    cols = []
    for name in EPH_COLUMNS:
        if name == "toe_sow":
            cols.append(nav.toe - nav.week * SECONDS_PER_WEEK)
        else:
            cols.append(getattr(nav, name))
    return np.ascontiguousarray(np.column_stack(cols).astype(np.float64))


# plausibility screen (module docstring, "Plausibility screen")
NEIGHBOUR_TOLERANCE_M = 30.0  # max orbit disagreement with an overlapping same-PRN data set
_A_NOMINAL_M, _A_TOLERANCE_M = 26_560e3, 500e3
_E_MAX = 0.03
_INCLINATION_RANGE_RAD = (np.deg2rad(40.0), np.deg2rad(70.0))
_RADIUS_RANGE_M = (25_000e3, 28_000e3)
_TOE_LSB_S = 16.0
_SCREEN_CACHE: OrderedDict = OrderedDict()
_SCREEN_CACHE_SIZE = 8


@dataclass
class EphemerisScreen:
    """Per record (arrays of length n_records): ok bool; reason str ('' when ok, else the
    first failed check); neighbour_disagreement_m: the smallest of the maximum position
    differences (m) to the overlapping same-PRN data sets (NaN when it has none)."""

    ok: np.ndarray
    reason: np.ndarray
    neighbour_disagreement_m: np.ndarray


def _positions(eph, idx, t):
    n = t.size
    pos, vel, clk, drift = np.empty((n, 3)), np.empty((n, 3)), np.empty(n), np.empty(n)
    if n:
        broadcast_orbit_into(eph, np.ascontiguousarray(idx, dtype=np.int64),
                             np.ascontiguousarray(t, dtype=np.float64), pos, vel, clk, drift)
    return pos


def _overlapping_pairs(nav: NavData, candidate: np.ndarray, half: np.ndarray):
    """(i, j) index pairs, i < j, of candidate records of one PRN that are different data
    sets (t_oe or IODE differ) with overlapping fit windows; and the overlap (lo, hi)."""
    pi, pj = [], []
    for p in np.unique(nav.prn[candidate]):
        k = candidate[nav.prn[candidate] == p]
        a, b = np.triu_indices(k.size, 1)
        pi.append(k[a])
        pj.append(k[b])
    i = np.concatenate(pi) if pi else np.zeros(0, dtype=np.int64)
    j = np.concatenate(pj) if pj else np.zeros(0, dtype=np.int64)
    lo = np.maximum(nav.toe[i] - half[i], nav.toe[j] - half[j])
    hi = np.minimum(nav.toe[i] + half[i], nav.toe[j] + half[j])
    other_set = (np.abs(nav.toe[i] - nav.toe[j]) > 0.5) | (nav.iode[i] != nav.iode[j])
    keep = other_set & (hi > lo)
    return i[keep], j[keep], lo[keep], hi[keep]


def screen_ephemeris_records(nav: NavData,
                             neighbour_tolerance_m: float = NEIGHBOUR_TOLERANCE_M
                             ) -> EphemerisScreen:
    """Plausibility screen of every broadcast record (module docstring: checks 1-3 and the
    justification of the bounds and of the 30 m neighbour tolerance). Health is not used."""
    n = nav.n_records
    reason = np.full(n, "", dtype=object)
    eph = ephemeris_matrix(nav) if n else np.zeros((0, len(EPH_COLUMNS)))
    half = 0.5 * 3600.0 * np.asarray(nav.fit_interval_h, dtype=float)

    def fail(mask, text):
        for k in np.flatnonzero(mask & (reason == "")):
            reason[k] = text(k)

    fail(~np.all(np.isfinite(eph), axis=1) | ~np.isfinite(half) | (half <= 0),
         lambda k: "non-finite element or fit interval")
    a = nav.sqrt_a ** 2
    fail(~(np.abs(a - _A_NOMINAL_M) <= _A_TOLERANCE_M),
         lambda k: f"semi-major axis {a[k] / 1e3:.1f} km outside "
                   f"{(_A_NOMINAL_M - _A_TOLERANCE_M) / 1e3:.0f}-"
                   f"{(_A_NOMINAL_M + _A_TOLERANCE_M) / 1e3:.0f} km")
    fail(~((nav.e >= 0.0) & (nav.e <= _E_MAX)),
         lambda k: f"eccentricity {nav.e[k]:.4g} outside [0, {_E_MAX}]")
    lo_i, hi_i = _INCLINATION_RANGE_RAD
    fail(~((nav.i0 >= lo_i) & (nav.i0 <= hi_i)),
         lambda k: f"inclination {np.rad2deg(nav.i0[k]):.2f} deg outside 40-70 deg")
    fail(nav.iode != np.mod(nav.iodc, 256),
         lambda k: f"IODE {nav.iode[k]:.0f} != IODC {nav.iodc[k]:.0f} mod 256")
    toe_sow = nav.toe - nav.week * SECONDS_PER_WEEK
    off_grid = np.abs(toe_sow - _TOE_LSB_S * np.round(toe_sow / _TOE_LSB_S))
    fail(off_grid > 1e-3, lambda k: f"t_oe {toe_sow[k]:.3f} s of week not a multiple of 16 s")
    fail(~(np.abs(nav.toc - nav.toe) <= half),
         lambda k: f"t_oc − t_oe = {nav.toc[k] - nav.toe[k]:.0f} s beyond half the fit interval")

    orbit_ok = np.flatnonzero(reason == "")
    t3 = (nav.toe[orbit_ok, None] + half[orbit_ok, None] * np.array([-1.0, 0.0, 1.0])).ravel()
    radius = np.linalg.norm(_positions(eph, np.repeat(orbit_ok, 3), t3), axis=1)
    radius = radius.reshape(-1, 3) if orbit_ok.size else np.zeros((0, 3))
    lo_r, hi_r = _RADIUS_RANGE_M
    bad_r = ~np.all((radius >= lo_r) & (radius <= hi_r), axis=1)
    for k, rr in zip(orbit_ok[bad_r], radius[bad_r]):
        reason[k] = (f"|r| {np.nanmin(rr) / 1e3:.0f}-{np.nanmax(rr) / 1e3:.0f} km over the fit "
                     "window outside 25 000-28 000 km")

    candidate = np.flatnonzero(reason == "")
    i, j, lo, hi = _overlapping_pairs(nav, candidate, half)
    ts = np.column_stack([lo, 0.5 * (lo + hi), hi]).ravel()
    diff = _positions(eph, np.repeat(i, 3), ts) - _positions(eph, np.repeat(j, 3), ts)
    pair_max = np.linalg.norm(diff, axis=1).reshape(-1, 3).max(axis=1) if i.size \
        else np.zeros(0)
    closest = np.full(n, np.inf)
    np.minimum.at(closest, i, pair_max)
    np.minimum.at(closest, j, pair_max)
    disagree = np.isfinite(closest) & (closest > neighbour_tolerance_m)
    fail(disagree, lambda k: f"orbit {closest[k] / 1e3:.3f} km from every overlapping "
                             f"data set of PRN{nav.prn[k]:02d} (tolerance "
                             f"{neighbour_tolerance_m:.0f} m)")
    closest[~np.isfinite(closest)] = np.nan
    return EphemerisScreen(reason == "", reason.astype(str), closest)


def plausible_record_mask(nav: NavData,
                          neighbour_tolerance_m: float = NEIGHBOUR_TOLERANCE_M) -> np.ndarray:
    """screen_ephemeris_records(nav).ok, cached by the content of nav (select_ephemeris
    runs once per epoch in the filters; the screen costs milliseconds)."""
    h = hashlib.blake2b(digest_size=16)
    for arr in (ephemeris_matrix(nav) if nav.n_records else np.zeros(0), nav.prn, nav.week,
                nav.iode, nav.iodc, nav.fit_interval_h):
        h.update(np.ascontiguousarray(arr).tobytes())
    key = (h.digest(), float(neighbour_tolerance_m))
    if key in _SCREEN_CACHE:
        _SCREEN_CACHE.move_to_end(key)
        return _SCREEN_CACHE[key]
    ok = screen_ephemeris_records(nav, neighbour_tolerance_m).ok
    ok.setflags(write=False)
    _SCREEN_CACHE[key] = ok
    while len(_SCREEN_CACHE) > _SCREEN_CACHE_SIZE:
        _SCREEN_CACHE.popitem(last=False)
    return ok


def select_ephemeris(nav: NavData, prn, t_gps, require_healthy: bool = True,
                     screen: bool = True) -> np.ndarray:
    """Index of the ephemeris record for each (prn, t): same PRN, healthy (unless
    require_healthy=False), passing the plausibility screen (unless screen=False), within
    half the fit interval of t_oe, closest t_oe. Returns int64 array (−1 where none)."""
    prn, t = np.broadcast_arrays(np.asarray(prn, dtype=np.int64),
                                 np.asarray(t_gps, dtype=np.float64))
    prn, t = prn.ravel(), t.ravel()
    out = np.full(prn.size, -1, dtype=np.int64)
    ok_rec = nav.health == 0 if require_healthy else np.ones(nav.n_records, dtype=bool)
    if screen:
        ok_rec = ok_rec & plausible_record_mask(nav)
    for p in np.unique(prn):
        q = np.flatnonzero(prn == p)
        cand = np.flatnonzero((nav.prn == p) & ok_rec)
        if cand.size == 0:
            continue
        dt = np.abs(t[q, None] - nav.toe[None, cand])
        dt[dt > 0.5 * 3600.0 * nav.fit_interval_h[None, cand] + 1e-6] = np.inf
        best = np.argmin(dt, axis=1)
        found = np.isfinite(dt[np.arange(q.size), best])
        out[q[found]] = cand[best[found]]
    return out


@njit(cache=True)
def _eccentric_anomaly(m, e):
    """Solve Kepler's equation M = E − e sin E by Newton iteration (|ΔE| < 1e-14 rad)."""
    big_e = m
    for _ in range(30):
        d = (big_e - e * np.sin(big_e) - m) / (1.0 - e * np.cos(big_e))
        big_e -= d
        if abs(d) < 1e-14:
            break
    return big_e


@njit(cache=True)
def broadcast_orbit_into(eph, idx, t, pos, vel, clk, drift):
    """IS-GPS-200 Table 20-IV user algorithm (with the rate terms for velocity) for query i
    at GPS time t[i] with record idx[i] of the packed matrix eph; idx < 0 → NaN outputs.
    pos m, vel m/s (ECEF of epoch t), clk s (incl. Δt_r = F e √A sin E, no T_GD), drift s/s."""
    for i in range(t.size):
        k = idx[i]
        if k < 0:
            for j in range(3):
                pos[i, j] = np.nan
                vel[i, j] = np.nan
            clk[i] = np.nan
            drift[i] = np.nan
            continue
        r = eph[k]
        a = r[_SQRTA] * r[_SQRTA]
        e = r[_E]
        tk = t[i] - r[_TOE]
        n = np.sqrt(GM_GPS / (a * a * a)) + r[_DN]
        big_e = _eccentric_anomaly(r[_M0] + n * tk, e)
        se, ce = np.sin(big_e), np.cos(big_e)
        one_m_ecos = 1.0 - e * ce
        sq = np.sqrt(1.0 - e * e)
        nu = np.arctan2(sq * se, ce - e)
        phi = nu + r[_OMEGA]
        s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
        u = phi + r[_CUS] * s2 + r[_CUC] * c2
        rad = a * one_m_ecos + r[_CRS] * s2 + r[_CRC] * c2
        inc = r[_I0] + r[_CIS] * s2 + r[_CIC] * c2 + r[_IDOT] * tk
        big_omega_dot = r[_OMEGADOT] - OMEGA_EARTH
        big_omega = r[_OMEGA0] + big_omega_dot * tk - OMEGA_EARTH * r[_TOE_SOW]
        su, cu = np.sin(u), np.cos(u)
        so, co = np.sin(big_omega), np.cos(big_omega)
        si, ci = np.sin(inc), np.cos(inc)
        xp, yp = rad * cu, rad * su
        pos[i, 0] = xp * co - yp * ci * so
        pos[i, 1] = xp * so + yp * ci * co
        pos[i, 2] = yp * si
        # rates (IS-GPS-200 Table 20-IV, "SV velocity" equations)
        e_dot = n / one_m_ecos
        nu_dot = e_dot * sq / one_m_ecos
        inc_dot = r[_IDOT] + 2.0 * nu_dot * (r[_CIS] * c2 - r[_CIC] * s2)
        u_dot = nu_dot * (1.0 + 2.0 * (r[_CUS] * c2 - r[_CUC] * s2))
        rad_dot = e * a * e_dot * se + 2.0 * nu_dot * (r[_CRS] * c2 - r[_CRC] * s2)
        xp_dot = rad_dot * cu - rad * u_dot * su
        yp_dot = rad_dot * su + rad * u_dot * cu
        vel[i, 0] = (-xp * big_omega_dot * so + xp_dot * co - yp_dot * so * ci
                     - yp * (big_omega_dot * co * ci - inc_dot * so * si))
        vel[i, 1] = (xp * big_omega_dot * co + xp_dot * so + yp_dot * co * ci
                     - yp * (big_omega_dot * so * ci + inc_dot * co * si))
        vel[i, 2] = yp_dot * si + yp * inc_dot * ci
        dtc = t[i] - r[_TOC]
        f_e_sqrta = F_RELATIVISTIC * e * r[_SQRTA]
        clk[i] = r[_AF0] + r[_AF1] * dtc + r[_AF2] * dtc * dtc + f_e_sqrta * se
        drift[i] = r[_AF1] + 2.0 * r[_AF2] * dtc + f_e_sqrta * ce * e_dot


def satellite_position_velocity_clock(nav: NavData, prn, t_gps, eph_index=None,
                                      eph: np.ndarray | None = None,
                                      screen: bool = True) -> SatelliteStates:
    """Broadcast satellite states at GPS time(s) t_gps (absolute s; the time of signal
    transmission). prn and t_gps broadcast against each other. eph_index: precomputed
    select_ephemeris result; eph: precomputed ephemeris_matrix(nav) (both optional);
    screen: plausibility screen in the selection (ignored when eph_index is given)."""
    prn_b, t_b = np.broadcast_arrays(np.asarray(prn, dtype=np.int64),
                                     np.asarray(t_gps, dtype=np.float64))
    t = np.ascontiguousarray(t_b.ravel())
    idx = select_ephemeris(nav, prn_b.ravel(), t, screen=screen) if eph_index is None \
        else np.ascontiguousarray(np.asarray(eph_index, dtype=np.int64).ravel())
    eph = ephemeris_matrix(nav) if eph is None else eph
    n = t.size
    pos, vel = np.empty((n, 3)), np.empty((n, 3))
    clk, drift = np.empty(n), np.empty(n)
    if n:
        broadcast_orbit_into(eph, idx, t, pos, vel, clk, drift)
    valid = (idx >= 0) & np.isfinite(t)
    tgd = np.where(valid, nav.tgd[np.maximum(idx, 0)] if nav.n_records else np.nan, np.nan)
    return SatelliteStates(pos, vel, clk, drift, tgd, idx, valid)


def transmit_time(nav: NavData, prn, t_receive, pseudorange, iterations: int = 2,
                  screen: bool = True):
    """GPS time of transmission from the receiver time tag and the pseudorange (m):
    t_sv = t_rx − P/c (satellite time, independent of the receiver clock error),
    t = t_sv − Δt_sv(t) iterated (IS-GPS-200 20.3.3.3.3.1). Δt_sv here excludes T_GD
    (its ≤ 30 ns changes the position by < 0.2 mm). screen: plausibility screen in the
    selection. Returns (t, eph_index)."""
    prn_b, t_rx, p = np.broadcast_arrays(np.asarray(prn, dtype=np.int64),
                                         np.asarray(t_receive, dtype=np.float64),
                                         np.asarray(pseudorange, dtype=np.float64))
    t_sv = (t_rx - p / C_LIGHT).ravel()
    idx = select_ephemeris(nav, prn_b.ravel(), t_sv, screen=screen)
    eph = ephemeris_matrix(nav)
    t = t_sv.copy()
    for _ in range(iterations):
        st = satellite_position_velocity_clock(nav, prn_b.ravel(), t, idx, eph)
        t = t_sv - np.where(st.valid, st.clock_bias, 0.0)
    return t.reshape(t_rx.shape), idx.reshape(t_rx.shape)


def earth_rotation_correction(sat_position, receiver_ecef, sat_velocity=None,
                              iterations: int = 2):
    """Rotate satellite ECEF vectors from the frame at transmission into the ECEF frame at
    reception: r' = R3(ω_e τ) r with τ = |r' − r_rcv| / c iterated. sat_position (n,3),
    receiver_ecef (3,) or (n,3). Returns (position (n,3), velocity (n,3) or None, τ (n,) s).
    Velocity is rotated by the same matrix (the ω_e × r frame term is not added)."""
    r = np.atleast_2d(np.asarray(sat_position, dtype=float))
    rcv = np.broadcast_to(np.asarray(receiver_ecef, dtype=float), r.shape)
    rot = r.copy()
    tau = np.linalg.norm(r - rcv, axis=1) / C_LIGHT
    for _ in range(iterations):
        theta = OMEGA_EARTH * tau
        c, s = np.cos(theta), np.sin(theta)
        rot[:, 0] = c * r[:, 0] + s * r[:, 1]
        rot[:, 1] = -s * r[:, 0] + c * r[:, 1]
        rot[:, 2] = r[:, 2]
        tau = np.linalg.norm(rot - rcv, axis=1) / C_LIGHT
    vel_rot = None
    if sat_velocity is not None:
        v = np.atleast_2d(np.asarray(sat_velocity, dtype=float))
        theta = OMEGA_EARTH * tau
        c, s = np.cos(theta), np.sin(theta)
        vel_rot = np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1],
                                   v[:, 2]])
    return rot, vel_rot, tau


def satellite_states_at_reception(nav: NavData, prn, t_receive, pseudorange, receiver_ecef,
                                  screen: bool = True):
    """Satellite states for observations received at t_receive (receiver time tags, absolute
    GPS s) with code pseudorange (m): transmission time from transmit_time, broadcast
    states there, then earth-rotation correction to the ECEF frame of reception for a
    receiver at receiver_ecef ((3,) or (n,3), approximate is fine: 1 km → < 1 cm).
    screen: plausibility screen in the ephemeris selection.
    Returns (SatelliteStates with rotated position/velocity, t_transmit (n,), τ (n,))."""
    prn = np.asarray(prn, dtype=np.int64).ravel()
    t_tx, idx = transmit_time(nav, prn, t_receive, pseudorange, screen=screen)
    t_tx, idx = np.ravel(t_tx), np.ravel(idx)
    st = satellite_position_velocity_clock(nav, np.broadcast_to(prn, t_tx.shape), t_tx, idx)
    pos, vel, tau = earth_rotation_correction(st.position, receiver_ecef, st.velocity)
    st.position, st.velocity = pos, vel
    return st, t_tx, tau
