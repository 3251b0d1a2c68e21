"""Single point positioning (SPP) from GPS L1 code by iterated weighted least squares.

Observation model for C1 of satellite s at receiver r (all m):
  P = ρ + c dt_r − c (Δt_sv − T_GD) + I_L1 + T + ε,
ρ = |r_sat − r_rcv| with the satellite at its transmission time rotated into the ECEF frame
of reception (gnss.ephemeris), Δt_sv with the relativistic term, T_GD for L1 single frequency
(IS-GPS-200 20.3.3.3.3.2), I_L1 the Klobuchar model (IS-GPS-200 20.3.3.5.2.5) when the nav
file has α/β (otherwise no ionosphere correction: metre-level errors remain, mostly common
to all satellites → absorbed by the clock), T Saastamoinen (gnss.troposphere).

Weights: σ² = a² + b² / sin² el (a, b in m). Satellites below the elevation mask are
dropped once a position is known (the first iteration from the earth centre uses all).
Outlier rejection: after convergence, while the largest |v_i| / σ_i exceeds
``outlier_k`` and more than 5 satellites remain, the worst satellite is removed and the
epoch re-solved. DOP from the unweighted (HᵀH)⁻¹ with the position block in local ENU.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gnss.constants import C_LIGHT, OMEGA_EARTH, SECONDS_PER_WEEK
from gnss.ephemeris import satellite_position_velocity_clock, transmit_time
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.rinex import NavData, ObsData, week_and_sow
from gnss.troposphere import saastamoinen_delay_scalar


@dataclass
class SppSolution:
    """One epoch: position (3,) ECEF m, clock_m = c·dt_r (m), dop [GDOP, PDOP, HDOP, VDOP],
    per input satellite: residuals (m, NaN if unused), used (bool), elevation/azimuth (rad);
    ok: converged with ≥ 4 satellites; n_iter; sigma0 = a-posteriori unit-weight σ."""

    position: np.ndarray
    clock_m: np.ndarray | float
    dop: np.ndarray
    residuals: np.ndarray
    used: np.ndarray
    elevation: np.ndarray
    azimuth: np.ndarray
    ok: bool
    n_iter: int
    sigma0: float


@dataclass
class SppSession:
    """Per epoch (n_ep,): t_gps, position (n_ep,3), clock_m, dop (n_ep,4), n_used, ok;
    residuals/elevation (n_ep, n_sat) in the column order of the ObsData."""

    t_gps: np.ndarray
    position: np.ndarray
    clock_m: np.ndarray
    dop: np.ndarray
    n_used: np.ndarray
    ok: np.ndarray
    residuals: np.ndarray
    elevation: np.ndarray


def klobuchar_delay(alpha, beta, lat, lon, azimuth, elevation, t_gps):
    """Klobuchar L1 ionospheric delay (m), IS-GPS-200 20.3.3.5.2.5. lat/lon/az/el in rad,
    t_gps absolute GPS seconds (only the time of day matters); arrays broadcast."""
    lat, lon, az, el, t = np.broadcast_arrays(*(np.asarray(v, float) for v in
                                               (lat, lon, azimuth, elevation, t_gps)))
    e_sc = el / np.pi
    psi = 0.0137 / (e_sc + 0.11) - 0.022
    phi_i = np.clip(lat / np.pi + psi * np.cos(az), -0.416, 0.416)
    lam_i = lon / np.pi + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
    _, sow = week_and_sow(t)
    t_local = np.mod(4.32e4 * lam_i + sow, 86400.0)
    slant = 1.0 + 16.0 * (0.53 - e_sc) ** 3
    amp = np.maximum(sum(alpha[n] * phi_m ** n for n in range(4)), 0.0)
    per = np.maximum(sum(beta[n] * phi_m ** n for n in range(4)), 72000.0)
    x = 2.0 * np.pi * (t_local - 50400.0) / per
    day = 5e-9 + amp * (1.0 - x * x / 2.0 + x ** 4 / 24.0)
    return C_LIGHT * slant * np.where(np.abs(x) < 1.57, day, 5e-9)


def elevation_azimuth(receiver_ecef, sat_ecef):
    """Elevation and azimuth (rad, azimuth clockwise from north) of satellites (n,3) seen
    from receiver_ecef (3,), plus the receiver's (lat, lon, h)."""
    lat, lon, h = ecef_to_geodetic(*np.asarray(receiver_ecef, float))
    c = ecef_to_enu_matrix(lat, lon)
    d = np.atleast_2d(sat_ecef) - receiver_ecef
    enu = d @ c.T
    el = np.arctan2(enu[:, 2], np.hypot(enu[:, 0], enu[:, 1]))
    az = np.mod(np.arctan2(enu[:, 0], enu[:, 1]), 2.0 * np.pi)
    return el, az, (lat, lon, h)


@njit(cache=True)
def klobuchar_delay_scalar(alpha, beta, lat, lon, azimuth, elevation, t_gps):
    """klobuchar_delay for one satellite (m), numba-compiled for the SPP kernel: the same
    IS-GPS-200 20.3.3.5.2.5 formulas with scalars (alpha, beta (4,) arrays), each operation
    in klobuchar_delay's order (powers ≥ 3 by pow(), as numpy) so the two agree bit for
    bit (tests/test_spp.py)."""
    e_sc = elevation / math.pi
    psi = 0.0137 / (e_sc + 0.11) - 0.022
    phi_i = min(max(lat / math.pi + psi * math.cos(azimuth), -0.416), 0.416)
    lam_i = lon / math.pi + psi * math.sin(azimuth) / math.cos(phi_i * math.pi)
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * math.pi)
    sow = t_gps - math.floor(t_gps / SECONDS_PER_WEEK) * SECONDS_PER_WEEK
    t_local = (4.32e4 * lam_i + sow) % 86400.0
    slant = 1.0 + 16.0 * math.pow(0.53 - e_sc, 3.0)
    phi3 = math.pow(phi_m, 3.0)
    amp = max(((alpha[0] + alpha[1] * phi_m) + alpha[2] * (phi_m * phi_m)) + alpha[3] * phi3,
              0.0)
    per = max(((beta[0] + beta[1] * phi_m) + beta[2] * (phi_m * phi_m)) + beta[3] * phi3,
              72000.0)
    x = 2.0 * math.pi * (t_local - 50400.0) / per
    if abs(x) < 1.57:
        return C_LIGHT * slant * (5e-9 + amp * (1.0 - x * x / 2.0 + math.pow(x, 4.0) / 24.0))
    return C_LIGHT * slant * 5e-9


@njit(cache=True)
def _spp_kernel(sat_ecef, sat_clock_l1, p, avail, t_receive, x, mask, sigma_a, sigma_b,
                outlier_k, iono, alpha, beta, tropo, max_iter, res, used, el, az, dop):
    """One SPP epoch (module doc), compiled: iterated weighted least squares with Sagnac
    rotation of the transmit-frame satellite positions sat_ecef (n,3) m into the frame of
    reception (2 iterations of τ = |r' − r_rcv|/c, as gnss.ephemeris.
    earth_rotation_correction), Saastamoinen + Klobuchar corrections, σ² = a² + b²/sin² el,
    elevation mask once the position is known (|r| > 6000 km), outlier rejection, DOP.
    x (4,) [x, y, z, c·dt_r] start, updated in place; res/used/el/az (n,) and dop (4,) are
    written. Returns (ok, n_iter, sigma0).

    Every operation is done in the order of the former numpy code (tests/reference_spp.py)
    and the matrix products go through np.dot (the same BLAS as numpy's @), so results are
    bit-identical to it: the RTK float filter downstream amplifies a last-bit change of its
    linearisation point (docs/DESIGN.md, "RTK and TC per-epoch kernels")."""
    n = p.size
    use = avail.copy()
    sel = np.zeros(n, np.bool_)
    sigma = np.ones(n)
    v = np.empty(n)
    h_all = np.ones((n, 4))                      # [-los, 1] rows
    sat = np.empty((n, 3))
    for i in range(n):
        el[i] = np.nan
        az[i] = np.nan
        res[i] = np.nan
    ok = False
    it = 0
    n_sel = 0
    while True:
        ok = False
        for it in range(1, max_iter + 1):
            known = math.sqrt((x[0] * x[0] + x[1] * x[1]) + x[2] * x[2]) > 6.0e6
            for i in range(n):                       # earth_rotation_correction
                r0, r1, r2 = sat_ecef[i, 0], sat_ecef[i, 1], sat_ecef[i, 2]
                d0, d1, d2 = r0 - x[0], r1 - x[1], r2 - x[2]
                tau = math.sqrt((d0 * d0 + d1 * d1) + d2 * d2) / C_LIGHT
                q0, q1 = r0, r1
                for _ in range(2):
                    th = OMEGA_EARTH * tau
                    c, s = math.cos(th), math.sin(th)
                    q0 = c * r0 + s * r1
                    q1 = -s * r0 + c * r1
                    d0, d1 = q0 - x[0], q1 - x[1]
                    tau = math.sqrt((d0 * d0 + d1 * d1) + d2 * d2) / C_LIGHT
                sat[i, 0], sat[i, 1], sat[i, 2] = q0, q1, r2
            lat = lon = h = 0.0
            if known:
                lat, lon, h = ecef_to_geodetic(x[0], x[1], x[2])
                d = np.empty((n, 3))
                for i in range(n):
                    for j in range(3):
                        d[i, j] = sat[i, j] - x[j]
                enu = np.dot(d, ecef_to_enu_matrix(lat, lon).T)
            n_sel = 0
            for i in range(n):
                d0, d1, d2 = sat[i, 0] - x[0], sat[i, 1] - x[1], sat[i, 2] - x[2]
                rho = math.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
                h_all[i, 0], h_all[i, 1], h_all[i, 2] = -(d0 / rho), -(d1 / rho), -(d2 / rho)
                corr = 0.0
                sel[i] = use[i]
                if known:
                    el[i] = math.atan2(enu[i, 2], np.hypot(enu[i, 0], enu[i, 1]))
                    az[i] = math.atan2(enu[i, 0], enu[i, 1]) % (2.0 * math.pi)
                    sel[i] = sel[i] and el[i] >= mask
                    if tropo:
                        corr += saastamoinen_delay_scalar(lat, h, el[i], 0.7)
                    if iono:
                        corr += klobuchar_delay_scalar(alpha, beta, lat, lon, az[i], el[i],
                                                       t_receive)
                    sin_el = math.sin(el[i])
                    if sin_el < 0.05:  # noqa: PLR1730 (np.maximum keeps NaN, max may not)
                        sin_el = 0.05
                    sigma[i] = math.sqrt(sigma_a * sigma_a + sigma_b * sigma_b
                                         / (sin_el * sin_el))
                v[i] = p[i] - (((rho + x[3]) - C_LIGHT * sat_clock_l1[i]) + corr)
                if sel[i]:
                    n_sel += 1
            if n_sel < 4:
                break
            hs = np.empty((n_sel, 4))
            hw = np.empty((n_sel, 4))
            wv = np.empty(n_sel)
            k = 0
            for i in range(n):
                if sel[i]:
                    w = 1.0 / (sigma[i] * sigma[i])
                    for j in range(4):
                        hs[k, j] = h_all[i, j]
                        hw[k, j] = h_all[i, j] * w
                    wv[k] = w * v[i]
                    k += 1
            dx = np.linalg.solve(np.dot(hs.T, hw), np.dot(hs.T, wv))
            for j in range(4):
                x[j] += dx[j]
            if math.sqrt((dx[0] * dx[0] + dx[1] * dx[1]) + dx[2] * dx[2]) < 1e-4 and known:
                ok = True
                hdx = np.dot(h_all, dx)
                for i in range(n):
                    res[i] = v[i] - hdx[i] if sel[i] else np.nan
                break
        if not ok:
            break
        worst = -1
        worst_val = -np.inf
        for i in range(n):
            val = abs(res[i]) / sigma[i] if sel[i] else -1.0
            if worst < 0 or val > worst_val:     # first maximum (np.argmax)
                worst, worst_val = i, val
        if worst_val > outlier_k and n_sel > 5:
            use[worst] = False
            continue
        break
    sigma0 = np.nan
    for i in range(n):
        used[i] = sel[i] and ok
    if ok:
        hu = np.empty((n_sel, 4))
        k = 0
        for i in range(n):
            if used[i]:
                for j in range(4):
                    hu[k, j] = h_all[i, j]
                k += 1
        q = np.linalg.solve(np.dot(hu.T, hu), np.eye(4))   # = np.linalg.inv (gesv on I)
        lat, lon, _ = ecef_to_geodetic(x[0], x[1], x[2])
        cen = ecef_to_enu_matrix(lat, lon)
        qe = np.dot(np.dot(cen, np.ascontiguousarray(q[:3, :3])), cen.T)
        e_, n_, u_ = qe[0, 0], qe[1, 1], qe[2, 2]
        dop[0] = math.sqrt(((e_ + n_) + u_) + q[3, 3])
        dop[1] = math.sqrt((e_ + n_) + u_)
        dop[2] = math.sqrt(e_ + n_)
        dop[3] = math.sqrt(u_)
        dof = n_sel - 4
        if dof > 0:
            ss = 0.0
            for i in range(n):
                if used[i]:
                    ss += (res[i] / sigma[i]) ** 2
            sigma0 = math.sqrt(ss / dof)
    else:
        for j in range(4):
            dop[j] = np.nan
        for i in range(n):
            res[i] = np.nan
    return ok, it, sigma0


def _solve(nav: NavData, st_position, sat_clock_l1, p, avail, t_receive, x,
           elevation_mask_deg, sigma_a, sigma_b, outlier_k, use_ionosphere, use_troposphere,
           max_iter):
    """Run _spp_kernel on one epoch's satellite states; returns an SppSolution."""
    n = p.size
    res, el, az = np.empty(n), np.empty(n), np.empty(n)
    used = np.zeros(n, dtype=bool)
    dop = np.empty(4)
    iono = bool(use_ionosphere and nav.ion_alpha is not None)
    alpha = np.asarray(nav.ion_alpha if iono else np.zeros(4), float)
    beta = np.asarray(nav.ion_beta if iono else np.zeros(4), float)
    ok, it, sigma0 = _spp_kernel(
        np.ascontiguousarray(st_position, float), np.ascontiguousarray(sat_clock_l1, float),
        p, np.ascontiguousarray(avail, bool), float(t_receive), x,
        float(np.deg2rad(elevation_mask_deg)), float(sigma_a), float(sigma_b),
        float(outlier_k), iono, alpha, beta, bool(use_troposphere), int(max_iter), res, used,
        el, az, dop)
    return SppSolution(position=x[:3].copy(), clock_m=float(x[3]), dop=dop, residuals=res,
                       used=used, elevation=el, azimuth=az, ok=bool(ok), n_iter=int(it),
                       sigma0=float(sigma0))


def solve_spp_epoch(nav: NavData, prn, pseudorange, t_receive, x0=None,
                    elevation_mask_deg: float = 15.0, sigma_a: float = 0.5,
                    sigma_b: float = 0.5, outlier_k: float = 5.0, use_ionosphere=True,
                    use_troposphere=True, max_iter: int = 10) -> SppSolution:
    """SPP for one epoch. prn (n,), pseudorange (n,) C1 in m (NaN allowed = not used),
    t_receive receiver time tag (absolute GPS s), x0 optional [x, y, z, c·dt_r] start.
    Transmission times and broadcast states by gnss.ephemeris, the least squares by the
    compiled _spp_kernel (the former numpy version: tests/reference_spp.py)."""
    prn = np.asarray(prn, dtype=np.int64)
    p = np.ascontiguousarray(pseudorange, dtype=float)
    t_tx, idx = transmit_time(nav, prn, t_receive, np.where(np.isfinite(p), p, 0.0))
    st = satellite_position_velocity_clock(nav, prn, t_tx, idx)
    avail = np.isfinite(p) & st.valid
    x = np.zeros(4) if x0 is None else np.asarray(x0, dtype=float).copy()
    return _solve(nav, st.position, st.clock_bias - st.tgd, p, avail, t_receive, x,
                  elevation_mask_deg, sigma_a, sigma_b, outlier_k, use_ionosphere,
                  use_troposphere, max_iter)


def solve_spp_session(obs: ObsData, nav: NavData, **options) -> SppSession:
    """SPP for every epoch of obs (C1 code), each epoch started from the previous solution
    (the first from the header APPROX POSITION when present). options → solve_spp_epoch.
    Transmission times and broadcast states of all epochs are computed in one vectorised
    call (element by element the same as solve_spp_epoch's), then the compiled kernel
    solves epoch by epoch."""
    n_ep, n_sat = obs.C1.shape
    pos = np.full((n_ep, 3), np.nan)
    clk = np.full(n_ep, np.nan)
    dop = np.full((n_ep, 4), np.nan)
    n_used = np.zeros(n_ep, dtype=np.int64)
    ok = np.zeros(n_ep, dtype=bool)
    res = np.full((n_ep, n_sat), np.nan)
    elev = np.full((n_ep, n_sat), np.nan)
    x0 = None
    if obs.approx_position_ecef is not None:
        x0 = np.r_[obs.approx_position_ecef, 0.0]
    opts = {"elevation_mask_deg": 15.0, "sigma_a": 0.5, "sigma_b": 0.5, "outlier_k": 5.0,
            "use_ionosphere": True, "use_troposphere": True, "max_iter": 10}
    unknown = set(options) - set(opts)
    if unknown:
        raise TypeError(f"solve_spp_session: unexpected options {sorted(unknown)}")
    opts.update(options)
    if n_ep == 0 or n_sat == 0:
        return SppSession(t_gps=obs.t_gps.copy(), position=pos, clock_m=clk, dop=dop,
                          n_used=n_used, ok=ok, residuals=res, elevation=elev)
    p_all = np.asarray(obs.C1, dtype=float)
    prn = np.broadcast_to(np.asarray(obs.prn, dtype=np.int64), p_all.shape)
    t_rx = np.broadcast_to(np.asarray(obs.t_gps, float)[:, None], p_all.shape)
    t_tx, idx = transmit_time(nav, prn, t_rx, np.where(np.isfinite(p_all), p_all, 0.0))
    st = satellite_position_velocity_clock(nav, prn.ravel(), t_tx.ravel(), idx.ravel())
    sat_pos = st.position.reshape(n_ep, n_sat, 3)
    clk_l1 = (st.clock_bias - st.tgd).reshape(n_ep, n_sat)
    avail_all = np.isfinite(p_all) & st.valid.reshape(n_ep, n_sat)
    for k in range(n_ep):
        x = np.zeros(4) if x0 is None else np.asarray(x0, dtype=float).copy()
        sol = _solve(nav, sat_pos[k], clk_l1[k], np.ascontiguousarray(p_all[k]),
                     avail_all[k], obs.t_gps[k], x, **opts)
        if not sol.ok:
            continue
        pos[k], clk[k], dop[k] = sol.position, sol.clock_m, sol.dop
        n_used[k], ok[k] = sol.used.sum(), True
        res[k], elev[k] = sol.residuals, sol.elevation
        x0 = np.r_[sol.position, sol.clock_m]
    return SppSession(t_gps=obs.t_gps.copy(), position=pos, clock_m=clk, dop=dop,
                      n_used=n_used, ok=ok, residuals=res, elevation=elev)


def filled_positions(spp: SppSession) -> np.ndarray:
    """(n_ep, 3) ECEF m: the session's positions, each epoch without a solution given the
    next solved epoch's (the last solved one after the end) — an approximate position for
    linearisation and Sagnac at every epoch. The session must have a solved epoch."""
    pos = spp.position.copy()
    ok = np.flatnonzero(spp.ok)
    if ok.size == 0:
        raise ValueError("filled_positions: no epoch has a single-point solution")
    fill = ok[np.clip(np.searchsorted(ok, np.arange(pos.shape[0])), 0, ok.size - 1)]
    pos[~spp.ok] = spp.position[fill[~spp.ok]]
    return pos
