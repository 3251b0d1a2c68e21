"""The numpy form of the statistics of gmis.tc_filter.satellite_phase_test before they were
compiled (gmis.dd_update_kernels.satellite_statistics): the reference
tests/test_dd_update_kernels.py holds the compiled path to. The decision from the
statistics (gmis.tc_filter.worst_satellite) is shared, not copied."""

import numpy as np

from gmis.tc_filter import worst_satellite


def satellite_statistics_numpy(res, a_pos, r_mat, sat_k):
    """(sats, n_rows, T_k, regular, vᵀR⁻¹v) as satellite_statistics, in numpy: one fit
    for all satellites, Ω − Ω₋ₖ = u_kᵀ (M_kk)⁻¹ u_k with u = R⁻¹v and M = R⁻¹ Q_v R⁻¹
    (Q_v = R − A N⁻¹ Aᵀ) over each satellite's 1×1 / 2×2 block."""
    w = np.linalg.inv(r_mat)
    wa = w @ a_pos
    n_inv = np.linalg.pinv(a_pos.T @ wa)
    v = res - a_pos @ (n_inv @ (wa.T @ res))
    u = w @ v
    m = w - wa @ n_inv @ wa.T
    sats, row_sat = np.unique(sat_k, return_inverse=True)
    n_rows = np.bincount(row_sat, minlength=sats.size)
    order = np.argsort(row_sat, kind="stable")
    first = order[np.r_[0, np.cumsum(n_rows)[:-1]]]
    second = np.where(n_rows > 1, order[np.minimum(np.r_[0, np.cumsum(n_rows)[:-1]] + 1,
                                                   res.size - 1)], first)
    m11, m22, m12 = m[first, first], m[second, second], m[first, second]
    u1, u2 = u[first], u[second]
    two = n_rows == 2
    det = np.where(two, m11 * m22 - m12 ** 2, m11)
    regular = (n_rows <= 2) & (det > 1e-8 * np.where(two, m11 * m22, np.diag(w)[first]))
    with np.errstate(divide="ignore", invalid="ignore"):
        t_all = np.where(two, (u1 ** 2 * m22 - 2.0 * u1 * u2 * m12 + u2 ** 2 * m11) / det,
                         u1 ** 2 / m11)
    return sats, n_rows, t_all, regular, float(v @ u)


def satellite_phase_test_numpy(res, a_pos, r_mat, sat_k, alpha: float, crit_cache=None):
    """satellite_phase_test with the numpy statistics."""
    return worst_satellite(res, a_pos, r_mat, sat_k,
                           satellite_statistics_numpy(res, a_pos, r_mat, sat_k), alpha,
                           {} if crit_cache is None else crit_cache)
