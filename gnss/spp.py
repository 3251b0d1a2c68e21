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

from dataclasses import dataclass

import numpy as np

from gnss.constants import C_LIGHT
from gnss.ephemeris import (
    earth_rotation_correction,
    satellite_position_velocity_clock,
    transmit_time,
)
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.rinex import NavData, ObsData, week_and_sow
from gnss.troposphere import saastamoinen_delay


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


def _dop(h_rows, receiver_ecef):
    q = np.linalg.inv(h_rows.T @ h_rows)
    lat, lon, _ = ecef_to_geodetic(*receiver_ecef)
    c = ecef_to_enu_matrix(lat, lon)
    q_enu = c @ q[:3, :3] @ c.T
    e, n, u = np.diag(q_enu)
    return np.sqrt([e + n + u + q[3, 3], e + n + u, e + n, u])


def solve_spp_epoch(nav: NavData, prn, pseudorange, t_receive, x0=None,
                    elevation_mask_deg: float = 15.0, sigma_a: float = 0.5,
                    sigma_b: float = 0.5, outlier_k: float = 5.0, use_ionosphere=True,
                    use_troposphere=True, max_iter: int = 10) -> SppSolution:
    """SPP for one epoch. prn (n,), pseudorange (n,) C1 in m (NaN allowed = not used),
    t_receive receiver time tag (absolute GPS s), x0 optional [x, y, z, c·dt_r] start."""
    prn = np.asarray(prn, dtype=np.int64)
    p = np.asarray(pseudorange, dtype=float)
    n = prn.size
    t_tx, idx = transmit_time(nav, prn, t_receive, np.where(np.isfinite(p), p, 0.0))
    st = satellite_position_velocity_clock(nav, prn, t_tx, idx)
    avail = np.isfinite(p) & st.valid
    sat_clock_l1 = st.clock_bias - st.tgd
    x = np.zeros(4) if x0 is None else np.asarray(x0, dtype=float).copy()
    mask = np.deg2rad(elevation_mask_deg)
    use = avail.copy()
    el = np.full(n, np.nan)
    az = np.full(n, np.nan)
    res = np.full(n, np.nan)
    sigma = np.ones(n)
    iono_ok = use_ionosphere and nav.ion_alpha is not None
    ok, it = False, 0
    while True:
        ok = False
        for it in range(1, max_iter + 1):
            known = np.linalg.norm(x[:3]) > 6.0e6
            sat_pos, _, _ = earth_rotation_correction(st.position, x[:3])
            d = sat_pos - x[:3]
            rho = np.linalg.norm(d, axis=1)
            los = d / rho[:, None]
            corr = np.zeros(n)
            sel = use.copy()
            if known:
                el, az, (lat, lon, h) = elevation_azimuth(x[:3], sat_pos)
                sel &= el >= mask
                if use_troposphere:
                    corr += saastamoinen_delay(lat, h, el)
                if iono_ok:
                    corr += klobuchar_delay(nav.ion_alpha, nav.ion_beta, lat, lon, az, el,
                                            t_receive)
                sin_el = np.maximum(np.sin(el), 0.05)
                sigma = np.sqrt(sigma_a ** 2 + sigma_b ** 2 / sin_el ** 2)
            if sel.sum() < 4:
                break
            model = rho + x[3] - C_LIGHT * sat_clock_l1 + corr
            v = p - model
            h_rows = np.column_stack([-los, np.ones(n)])[sel]
            w = 1.0 / sigma[sel] ** 2
            n_mat = h_rows.T @ (h_rows * w[:, None])
            dx = np.linalg.solve(n_mat, h_rows.T @ (w * v[sel]))
            x += dx
            if np.linalg.norm(dx[:3]) < 1e-4 and known:
                ok = True
                res = np.where(sel, v - np.column_stack([-los, np.ones(n)]) @ dx, np.nan)
                break
        if not ok:
            break
        norm_res = np.abs(res) / sigma
        norm_res[~sel] = -1.0
        worst = int(np.argmax(norm_res))
        if norm_res[worst] > outlier_k and sel.sum() > 5:
            use[worst] = False
            continue
        break
    used = sel if ok else np.zeros(n, dtype=bool)
    if ok:
        h_used = np.column_stack([-los, np.ones(n)])[used]
        dop = _dop(h_used, x[:3])
        dof = used.sum() - 4
        sigma0 = float(np.sqrt(np.sum((res[used] / sigma[used]) ** 2) / dof)) if dof > 0 \
            else float("nan")
    else:
        dop, sigma0, res = np.full(4, np.nan), float("nan"), np.full(n, np.nan)
    return SppSolution(position=x[:3].copy(), clock_m=float(x[3]), dop=dop, residuals=res,
                       used=used, elevation=el, azimuth=az, ok=ok, n_iter=it, sigma0=sigma0)


def solve_spp_session(obs: ObsData, nav: NavData, **options) -> SppSession:
    """SPP for every epoch of obs (C1 code), each epoch started from the previous solution
    (the first from the header APPROX POSITION when present). options → solve_spp_epoch."""
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
    for k in range(n_ep):
        sol = solve_spp_epoch(nav, obs.prn, obs.C1[k], obs.t_gps[k], x0=x0, **options)
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
