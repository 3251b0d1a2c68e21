"""gmis.kalman_update_reference: the numpy Kalman update, per-group outlier test and VCE
terms against their textbook forms (001 §5.2)."""

import numpy as np
from scipy import stats

from gmis.kalman_update_reference import (
    OutlierCriticalValues,
    group_outlier_test,
    group_vce_terms,
    kalman_update,
)


def _problem(seed=0, n=6, m=5):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    p = a @ a.T + n * np.eye(n)
    h = rng.normal(size=(m, n))
    b = rng.normal(size=(m, m))
    r = 0.1 * (b @ b.T) + 0.5 * np.eye(m)
    return rng.normal(size=n), p, h, rng.normal(size=m), r


def test_update_is_the_kalman_gain_form():
    x, p, h, d, r = _problem()
    x1, p1 = x.copy(), p.copy()
    dmat, dinv_d = kalman_update(x1, p1, h, d, r)
    s = h @ p @ h.T + r
    k = p @ h.T @ np.linalg.inv(s)
    np.testing.assert_allclose(dmat, s, rtol=1e-13)
    np.testing.assert_allclose(dinv_d, np.linalg.solve(s, d), rtol=1e-10)
    np.testing.assert_allclose(x1, x + k @ d, rtol=1e-10)
    np.testing.assert_allclose(p1, (np.eye(x.size) - k @ h) @ p, rtol=1e-9, atol=1e-12)
    assert np.array_equal(p1, p1.T)


def test_vce_terms_sum_to_the_total_redundancy():
    x, p, h, d, r = _problem(1)
    groups = np.array([0, 0, 1, 1, 3])
    dmat, dinv_d = kalman_update(x.copy(), p.copy(), h, d, r)
    t = group_vce_terms(r, dmat, dinv_d, groups, 4)
    dinv = np.linalg.inv(dmat)
    assert t.n_obs.tolist() == [2, 2, 0, 1] and t.vpv[2] == 0.0 and t.redundancy[2] == 0.0
    np.testing.assert_allclose(t.v, -r @ dinv @ d, rtol=1e-10)
    # block traces of R D⁻¹ over a block-diagonal R add up to tr(R D⁻¹) = m − tr(H P Hᵀ D⁻¹)
    r_blk = np.zeros_like(r)
    for g in (0, 1, 3):
        i = np.flatnonzero(groups == g)
        r_blk[np.ix_(i, i)] = r[np.ix_(i, i)]
    t = group_vce_terms(r_blk, h @ p @ h.T + r_blk, np.linalg.solve(h @ p @ h.T + r_blk, d),
                        groups, 4)
    s = h @ p @ h.T + r_blk
    np.testing.assert_allclose(t.redundancy.sum(), 5 - np.trace(h @ p @ h.T @ np.linalg.inv(s)),
                               rtol=1e-10)
    i = np.flatnonzero(groups == 0)
    v = -r_blk @ np.linalg.solve(s, d)
    np.testing.assert_allclose(t.vpv[0], v[i] @ np.linalg.solve(r_blk[np.ix_(i, i)], v[i]),
                               rtol=1e-10)


def test_outlier_test_rejects_a_blunder_row_then_a_whole_group():
    crit = OutlierCriticalValues.at(0.001)
    assert np.isclose(crit.z, stats.norm.ppf(1 - 0.0005))
    assert np.isclose(crit.chi2(3), stats.chi2.ppf(0.999, 3))
    assert np.isclose(crit.chi2(500), stats.chi2.ppf(0.999, 500))     # beyond the table
    s = np.eye(6)
    groups = {0: np.arange(0, 3), 1: np.arange(3, 6)}
    d = np.array([0.1, 8.0, -0.2, 0.3, 0.1, -0.4])
    keep, rejected = group_outlier_test(d, s, groups, crit)
    assert keep.tolist() == [True, False, True, True, True, True] and rejected == {0: 1, 1: 0}
    # no single row beyond z = 3.29, but χ²(3) = 3·3.2² = 30.7 > 16.3: the whole group goes
    d = np.array([0.0, 0.0, 0.0, 3.2, -3.2, 3.2])
    keep, rejected = group_outlier_test(d, s, groups, crit)
    assert keep.tolist() == [True, True, True, False, False, False] and rejected == {0: 0, 1: 3}
    off = OutlierCriticalValues.at(0.0)
    keep, _ = group_outlier_test(np.full(6, 1e6), s, groups, off)
    assert keep.all()
