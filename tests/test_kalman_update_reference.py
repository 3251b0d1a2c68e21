"""gmis.kalman_update_reference: the numpy Kalman update, per-group outlier test and VCE
terms against their textbook forms (001 §5.2)."""

import numpy as np
from scipy import stats

from gmis import gmikf
from gmis.kalman_update_reference import (
    OutlierCriticalValues,
    group_outlier_test,
    group_vce_terms,
    kalman_update,
)
from gmis.state import I_HEADING, I_SG


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


# ---------------------------------------------------------------- the numba kernel stages
# gmis.gmikf computes the same update in its own loops (sparse H rows, factored update
# W = L⁻¹ H P); these tests run its stages on one epoch and compare with the numpy
# reference above (issue 12: one reference of the update and the outlier test).


def _kernel_epoch(seed, slots, blunder=None, n=27):
    """A workspace and records for one epoch with the given slots present: P SPD (exactly
    symmetric), H rows with the sparsity of the real models (zeros kept), R diagonal."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    p = a @ a.T / n + 0.1 * np.eye(n)
    p = 0.5 * (p + p.T)
    x = rng.normal(size=n)
    x[I_HEADING] = 1.0
    ws = gmikf.make_workspace(n, 18)
    for i in slots:
        row = rng.normal(size=n)
        row[rng.random(n) < 0.6] = 0.0       # sparse rows like the real H
        row[i % n] = 1.0
        ws.h_all[i] = row
        ws.hx_all[i] = rng.normal()
        ws.r_all[i] = rng.uniform(0.5, 2.0)
        ws.present[i] = True
    d_true = rng.normal(size=len(slots)) * 0.3
    for k, i in enumerate(slots):
        ws.z_all[i] = ws.hx_all[i] + d_true[k] + (blunder[1] if blunder and blunder[0] == i
                                                    else 0.0)
    e = 1
    return x, p, ws, _records(3, n, 18), e


def _records(e_total, n, nw):
    ns = gmikf.N_SLOTS
    shapes = {"x": (e_total, n), "sd": (e_total, n), "cov_blocks": (e_total, 3, 3, 3),
              "vw": (e_total, nw), "rw": (e_total, nw), "rx": (e_total,),
              "helmert_s": (ns + nw, ns + nw), "helmert_totals": (2,),
              "helmert_trunc": (ns + nw + 1,)}
    dtypes = {"rejected": np.int8, "nobs": np.int64}
    return gmikf.EpochRecords(*(np.zeros(shapes.get(f, (e_total, ns)), dtypes.get(f, float))
                                if f != "nobs" else np.zeros(e_total, np.int64)
                                for f in gmikf.EpochRecords._fields))


SLOTS = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12]      # IMU, GNSS position, heading


def test_kernel_innovations_and_update_equal_the_reference():
    x, p, ws, rec, e = _kernel_epoch(3, SLOTS)
    h = ws.h_all[SLOTS].copy()
    r = np.diag(ws.r_all[SLOTS])
    d = ws.z_all[SLOTS] - ws.hx_all[SLOTS]
    m = gmikf.innovations(e, p, ws, rec)
    assert m == len(SLOTS) and list(ws.used[:m]) == SLOTS
    np.testing.assert_allclose(ws.d[:m], d, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ws.hp[:m], h @ p, rtol=1e-13, atol=1e-13)
    x_ref, p_ref = x.copy(), p.copy()
    dmat, dinv_d = kalman_update(x_ref, p_ref, h, d, r)
    np.testing.assert_allclose(ws.s[:m, :m], dmat, rtol=1e-13, atol=1e-13)
    x_k, p_k = x.copy(), p.copy()
    assert gmikf.kalman_update(x_k, p_k, m, ws)
    x_ref[I_HEADING] %= 2 * np.pi
    np.testing.assert_allclose(x_k, x_ref, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(p_k, p_ref, rtol=1e-10, atol=1e-12)
    assert np.array_equal(p_k, p_k.T)
    np.testing.assert_allclose(ws.sinv_d[:m, 0], dinv_d, rtol=1e-10, atol=1e-12)
    # the kernel really changed the state (the test can fail)
    assert np.abs(x_k - x).max() > 1e-3


def test_kernel_outlier_test_keeps_the_rows_the_reference_keeps():
    crit = OutlierCriticalValues.at(0.001)
    chi2_crit = np.concatenate([[0.0], crit.chi2_table[1:gmikf.N_SLOTS + 1]])
    for blunder in (None, (7, 40.0), (2, -25.0)):
        x, p, ws, rec, e = _kernel_epoch(5, SLOTS, blunder)
        m = gmikf.innovations(e, p, ws, rec)
        dmat, d = ws.s[:m, :m].copy(), ws.d[:m].copy()
        groups = {}
        for g, (g0, gn) in enumerate(zip(gmikf.GROUP_START, gmikf.GROUP_SIZE, strict=True)):
            idx = np.flatnonzero((np.array(SLOTS) >= g0) & (np.array(SLOTS) < g0 + gn))
            if idx.size:
                groups[g] = idx
            gmikf.group_outlier_test(e, g0, gn, m, chi2_crit, crit.z, ws, rec)
        keep, _ = group_outlier_test(d, dmat, groups, crit)
        assert np.array_equal(rec.rejected[e, SLOTS] == 0, keep)
        assert keep.all() == (blunder is None)
        mm = gmikf.drop_rejected(e, m, ws, rec)
        kept = [s for s, k in zip(SLOTS, keep, strict=True) if k]
        assert mm == len(kept) and list(ws.used[:mm]) == kept
        np.testing.assert_allclose(ws.s[:mm, :mm], dmat[np.ix_(keep, keep)], rtol=1e-13,
                                   atol=1e-13)
        x_k, p_k = x.copy(), p.copy()
        assert gmikf.kalman_update(x_k, p_k, mm, ws)
        x_ref, p_ref = x.copy(), p.copy()
        kalman_update(x_ref, p_ref, ws.h_all[kept], d[keep], np.diag(ws.r_all[kept]))
        x_ref[I_HEADING] %= 2 * np.pi
        np.testing.assert_allclose(x_k, x_ref, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(p_k, p_ref, rtol=1e-10, atol=1e-12)


def test_kernel_scale_gain_drop_is_the_consider_update():
    """drop_imu_scale_gain: x_S −= K[S, imu] d_imu, P_SS += Δ D_imu Δᵀ with Δ = K[S, imu]
    (the gain of the IMU rows on the scale factors removed, Joseph form)."""
    for slots in (SLOTS, [0, 1, 2, 3, 4, 5]):
        x, p, ws, rec, e = _kernel_epoch(7, slots)
        m = gmikf.innovations(e, p, ws, rec)
        h = ws.h_all[slots].copy()
        r = np.diag(ws.r_all[slots])
        d = ws.d[:m].copy()
        dmat = h @ p @ h.T + r
        gain = p @ h.T @ np.linalg.inv(dmat)
        x_ref = x + gain @ d
        p_ref = p - gain @ h @ p
        s_rows = slice(I_SG, I_SG + 6)
        delta = gain[s_rows, :6]
        x_ref[s_rows] -= delta @ d[:6]
        p_ref[s_rows, s_rows] += delta @ dmat[:6, :6] @ delta.T
        x_ref[I_HEADING] %= 2 * np.pi
        x_k, p_k = x.copy(), p.copy()
        assert gmikf.kalman_update(x_k, p_k, m, ws)
        gmikf.drop_imu_scale_gain(x_k, p_k, m, ws)
        np.testing.assert_allclose(x_k, x_ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(p_k, p_ref, rtol=1e-9, atol=1e-11)
        assert np.abs(delta @ d[:6]).max() > 1e-3
