"""The pure-numpy single point positioning of gnss.spp before its per-epoch least squares
was compiled with numba (kept verbatim as the reference of tests/test_spp.py): the same
model, vectorised over the satellites of one epoch with numpy calls."""

import numpy as np

from gnss.constants import C_LIGHT
from gnss.ephemeris import (
    earth_rotation_correction,
    satellite_position_velocity_clock,
    transmit_time,
)
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.rinex import NavData
from gnss.spp import SppSolution, elevation_azimuth, klobuchar_delay
from gnss.troposphere import saastamoinen_delay


def _dop(h_rows, receiver_ecef):
    q = np.linalg.inv(h_rows.T @ h_rows)
    lat, lon, _ = ecef_to_geodetic(*receiver_ecef)
    c = ecef_to_enu_matrix(lat, lon)
    q_enu = c @ q[:3, :3] @ c.T
    e, n, u = np.diag(q_enu)
    return np.sqrt([e + n + u + q[3, 3], e + n + u, e + n, u])


def solve_spp_epoch_numpy(nav: NavData, prn, pseudorange, t_receive, x0=None,
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
