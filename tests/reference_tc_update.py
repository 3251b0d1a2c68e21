"""The numpy form of gmis.tc_filter.satellite_phase_test before its statistics were
compiled (gmis.dd_update_kernels.satellite_statistics): the reference
tests/test_dd_update_kernels.py holds the compiled path to."""

import numpy as np

from gmis.critical_values import chi2_quantile
from gmis.tc_filter import SATELLITE_TEST_MIN_REDUNDANCY


def satellite_phase_test_numpy(res, a_pos, r_mat, sat_k, alpha: float, crit_cache=None):
    """Per-satellite outlier test of fixed DD phases (001 §5.2 style, on the fixed
    solution). res (m,) residuals z − h(x) (m) of the DD phase rows with fixed
    ambiguities, a_pos (m, 3) their partials ∂h/∂p (position), r_mat (m, m) their
    covariance σ²M, sat_k (m,) each row's satellite. The residuals are fitted by a
    position correction δp (weights R⁻¹); Ω = vᵀR⁻¹v of that fit, Ω₋ₖ the same without
    satellite k's rows; T_k = Ω − Ω₋ₖ is χ²(n_k) when the integers are right (n_k rows
    of k). A satellite is tested when the fit without it keeps ≥
    SATELLITE_TEST_MIN_REDUNDANCY dof. Returns the satellite with the largest
    T_k / χ²(1 − α/n_tested, n_k) when that exceeds 1 (Bonferroni over the n_tested
    satellites), else None. crit_cache: optional dict for the critical values."""
    crit_cache = {} if crit_cache is None else crit_cache
    # one fit for all satellites: Ω − Ω₋ₖ = u_kᵀ (M_kk)⁻¹ u_k with u = R⁻¹v and
    # M = R⁻¹ Q_v R⁻¹ (Q_v = R − A N⁻¹ Aᵀ), the group statistic of k's rows (Baarda's test of
    # a bias in those rows equals the fall of vᵀR⁻¹v when they are left out)
    w = np.linalg.inv(r_mat)
    wa = w @ a_pos
    n_inv = np.linalg.pinv(a_pos.T @ wa)
    v = res - a_pos @ (n_inv @ (wa.T @ res))
    u = w @ v
    m = w - wa @ n_inv @ wa.T
    every = np.arange(res.size)

    def omega(rows):
        w_r = np.linalg.inv(r_mat[np.ix_(rows, rows)])
        aa, rr = a_pos[rows], res[rows]
        v_r = rr - aa @ np.linalg.lstsq(aa.T @ w_r @ aa, aa.T @ w_r @ rr, rcond=None)[0]
        return float(v_r @ w_r @ v_r)

    # the 1×1 / 2×2 blocks M_kk of every satellite (its L1 and L2 rows) at once
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
    tests = []
    for i, k in enumerate(sats):
        n_k = int(n_rows[i])
        if res.size - n_k - a_pos.shape[1] < SATELLITE_TEST_MIN_REDUNDANCY:
            continue
        # k's rows not redundant (the rest leaves the position undetermined): refit
        t_k = float(t_all[i]) if regular[i] else float(v @ u) - omega(every[sat_k != k])
        tests.append((int(k), n_k, t_k))
    worst, worst_excess = None, 1.0
    for k, n_k, t in tests:
        key = (alpha, len(tests), n_k)
        if key not in crit_cache:
            crit_cache[key] = float(chi2_quantile(1.0 - alpha / len(tests), n_k))
        if t / crit_cache[key] > worst_excess:
            worst, worst_excess = k, t / crit_cache[key]
    return worst
