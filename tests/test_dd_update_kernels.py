"""gmis.dd_update_kernels (the compiled pieces of the tightly coupled DD update) against
their numpy references: gmis.kalman_update_reference (outlier test, VCE terms),
tests/reference_tc_update.py (the per-satellite phase test before compilation) and the
numpy form of the TDCP slip test's data-snooping step. The decisions must be the same;
the figures agree to 1e-9 relative (LAPACK through scipy in numba, through numpy there)."""

import numpy as np
import pytest

from gmis import dd_update_kernels as kern
from gmis import kalman_update_reference as ref
from gmis.tc_filter import satellite_phase_test
from tests.reference_tc_update import satellite_phase_test_numpy, satellite_statistics_numpy


def _dd_update_case(rng, sizes, n_states=12):
    """Innovations of DD groups with the given row counts: R block-diagonal σ²·M
    (M = diag + 1, 001 eq. 5.1.10), H random, P random SPD; d drawn from D."""
    blocks, groups = [], []
    for g, n in enumerate(sizes):
        if n == 0:
            continue
        sig2 = rng.uniform(0.5, 2.0) * 10.0 ** rng.uniform(-6, 0)
        blocks.append(sig2 * (np.diag(rng.uniform(0.5, 2.0, n)) + rng.uniform(0.5, 1.5)))
        groups += [g] * n
    m = len(groups)
    r = np.zeros((m, m))
    pos = 0
    for b in blocks:
        r[pos:pos + b.shape[0], pos:pos + b.shape[0]] = b
        pos += b.shape[0]
    h = rng.normal(size=(m, n_states))
    a = rng.normal(size=(n_states, n_states))
    p = 1e-3 * (a @ a.T + n_states * np.eye(n_states))
    dmat = h @ p @ h.T + r
    d = np.linalg.cholesky(dmat) @ rng.normal(size=m)
    return d, dmat, r, np.array(groups, dtype=np.int64)


def test_outlier_test_decides_as_the_numpy_reference():
    """Same rows kept and the same counts per group as kalman_update_reference on 400
    random updates, with single-row blunders (z test) and small shifts of a whole group
    (χ² test only) mixed in; both kinds of rejection occur."""
    rng = np.random.default_rng(11)
    crit = ref.OutlierCriticalValues.at(0.01)
    kinds_seen = set()
    for trial in range(400):
        sizes = [int(n) for n in rng.integers(0, 10, 4)]
        if sum(sizes) == 0:
            continue
        d, dmat, _, groups = _dd_update_case(rng, sizes)
        sd = np.sqrt(np.diag(dmat))
        if trial % 3 == 1:
            i = int(rng.integers(d.size))
            d[i] += 5.0 * sd[i]
        elif trial % 3 == 2:
            d += 2.2 * sd * (groups == groups[0])
        group_rows = {g: np.flatnonzero(groups == g) for g in range(4) if sizes[g]}
        keep_ref, rej_ref = ref.group_outlier_test(d, dmat, group_rows, crit)
        keep, rej = kern.group_outlier_test(d, dmat, groups, 4, crit)
        assert np.array_equal(keep, keep_ref) and rej == rej_ref
        for g, n in rej.items():
            if n:
                kinds_seen.add("row" if n < sizes[g] else "group")
    assert kinds_seen == {"row", "group"}


def test_vce_terms_equal_the_numpy_reference():
    """vpv, redundancy, n_obs, v and the standardized residuals of group_vce_terms equal
    kalman_update_reference's to 1e-9 relative on 200 random updates (1-4 groups)."""
    rng = np.random.default_rng(12)
    for _ in range(200):
        sizes = [int(n) for n in rng.integers(0, 9, 4)]
        if sum(sizes) == 0:
            continue
        d, dmat, r, groups = _dd_update_case(rng, sizes)
        dinv_d = np.linalg.solve(dmat, d)
        want = ref.group_vce_terms(r, dmat, dinv_d, groups, 4)
        got = kern.group_vce_terms(r, dmat, dinv_d, groups, 4)
        assert np.array_equal(got.n_obs, want.n_obs)
        for name in ("vpv", "redundancy", "v", "standardized"):
            np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-9,
                                       atol=1e-300, err_msg=name)
        assert got.redundancy.sum() == pytest.approx(np.trace(r @ np.linalg.inv(dmat)),
                                                     rel=1e-9)


def _phase_case(rng, n_sat, two_freq, bias_row=None):
    rows = 2 * n_sat if two_freq else n_sat
    a_pos = rng.normal(size=(n_sat, 3))
    a_pos = np.vstack([a_pos] * 2) if two_freq else a_pos
    sat_k = np.concatenate([np.arange(n_sat)] * (2 if two_freq else 1)) + 3
    cof = 1e-6 * (np.diag(rng.uniform(0.5, 2.0, n_sat)) + 1.0)
    r_mat = np.kron(np.diag([1.0, 1.6]), cof) if two_freq else cof
    res = np.linalg.cholesky(r_mat) @ rng.normal(size=rows)
    if bias_row is not None:
        res[bias_row % rows] += 0.05
    return res, a_pos, r_mat, sat_k


def test_satellite_phase_test_names_what_the_numpy_form_named():
    """satellite_phase_test (compiled statistics) against its numpy form before
    compilation on 600 random L1 and L1+L2 sets of 4-10 satellites, half with a 5 cm bias
    on one row: the same satellite (or None) every time, both outcomes occurring, and
    the statistics equal to 1e-9 relative."""
    rng = np.random.default_rng(13)
    named = none = 0
    for trial in range(600):
        n_sat = int(rng.integers(4, 11))
        res, a_pos, r_mat, sat_k = _phase_case(rng, n_sat, trial % 2 == 0,
                                               int(rng.integers(100)) if trial % 4 < 2
                                               else None)
        want = satellite_phase_test_numpy(res, a_pos, r_mat, sat_k, 1e-4)
        assert satellite_phase_test(res, a_pos, r_mat, sat_k, 1e-4) == want
        named += want is not None
        none += want is None
        sats, n_rows, t_all, regular, vu = kern.satellite_statistics(res, a_pos, r_mat,
                                                                          sat_k)
        ref = satellite_statistics_numpy(res, a_pos, r_mat, sat_k)
        assert np.array_equal(sats, ref[0]) and np.array_equal(n_rows, ref[1])
        assert np.array_equal(regular, ref[3])
        np.testing.assert_allclose(t_all, ref[2], rtol=1e-9, atol=1e-12)
        w = np.linalg.inv(r_mat)
        v = res - a_pos @ np.linalg.solve(a_pos.T @ w @ a_pos, a_pos.T @ w @ res)
        assert vu == pytest.approx(v @ w @ v, rel=1e-9)
        assert np.array_equal(sats, np.unique(sat_k)) and regular.all()
        for k, t in zip(sats, t_all):
            keep = sat_k != k
            wk = np.linalg.inv(r_mat[np.ix_(keep, keep)])
            ak, rk = a_pos[keep], res[keep]
            vk = rk - ak @ np.linalg.solve(ak.T @ wk @ ak, ak.T @ wk @ rk)
            assert t == pytest.approx(v @ w @ v - vk @ wk @ vk, rel=1e-7, abs=1e-9)
    assert named > 100 and none > 100


def test_satellite_phase_test_refits_a_satellite_whose_rows_are_not_redundant():
    """A satellite whose partials no other satellite shares (its M block ~ 0: irregular)
    is tested by the explicit refit, as in the numpy form: the same answer."""
    rng = np.random.default_rng(14)
    for _ in range(50):
        res, a_pos, r_mat, sat_k = _phase_case(rng, 7, False, int(rng.integers(7)))
        a_pos[:, 2] = 0.0
        a_pos[0, 2] = 1.0            # only satellite 0 sees the third axis
        _, _, _, regular, _ = kern.satellite_statistics(res, a_pos, r_mat, sat_k)
        assert not regular[0]
        assert satellite_phase_test(res, a_pos, r_mat, sat_k, 1e-4) == \
            satellite_phase_test_numpy(res, a_pos, r_mat, sat_k, 1e-4)


def test_tdcp_snooping_step_equals_the_numpy_fit():
    """tdcp_snooping_step: the row of the largest w = |v|/√r and its v, r equal the numpy
    fit's (the form _tdcp_slip_test had) on 300 random geometries, with a jump on one row
    in half of them."""
    rng = np.random.default_rng(15)
    for trial in range(300):
        n = int(rng.integers(6, 12))
        los = rng.normal(size=(n, 3))
        a = np.column_stack([-los / np.linalg.norm(los, axis=1)[:, None], np.ones(n)])
        y = 0.003 * rng.normal(size=n)
        if trial % 2:
            y[int(rng.integers(n))] += 0.19
        n_inv = np.linalg.inv(a.T @ a)
        r = np.maximum(1.0 - np.einsum("ij,jk,ik->i", a, n_inv, a), 1e-12)
        v = y - a @ (n_inv @ (a.T @ y))
        best = int(np.argmax(np.abs(v) / np.sqrt(r)))
        got = kern.tdcp_snooping_step(a, y)
        assert got[0] == best
        assert got[1] == pytest.approx(v[best], rel=1e-9, abs=1e-15)
        assert got[2] == pytest.approx(r[best], rel=1e-9)


def test_tdcp_fit_rows_equal_the_numpy_form():
    """tdcp_fit_rows: the satellites of the fit (present before, not flagged, phase at both
    epochs, ambiguity initialised) and y, A equal the numpy form _tdcp_slip_test had, on
    random epochs with missing phases, flags and satellites absent before."""
    rng = np.random.default_rng(16)
    for _ in range(200):
        n, n_prev = int(rng.integers(4, 12)), int(rng.integers(4, 12))
        idx = np.where(rng.random(n) < 0.8, rng.integers(0, n_prev, n), -1).astype(np.int64)
        slip = rng.random(n) < 0.1
        sd = np.where(rng.random(n) < 0.9, rng.normal(0, 1e3, n), np.nan)
        prev_sd = np.where(rng.random(n_prev) < 0.9, rng.normal(0, 1e3, n_prev), np.nan)
        init = rng.random(n) < 0.9
        r_ant = rng.normal(0, 1e6, 3)
        sat = rng.normal(0, 2e7, (n, 3))
        prev_sat = rng.normal(0, 2e7, (n_prev, 3))
        los = sat - r_ant
        rho = np.linalg.norm(los, axis=1)
        base, prev_base = rng.uniform(2e7, 2.5e7, n), rng.uniform(2e7, 2.5e7, n_prev)
        have = idx >= 0
        rows = np.flatnonzero(have & ~slip & np.isfinite(sd)
                              & np.isfinite(prev_sd[np.where(have, idx, 0)]) & init)
        i_p = idx[rows]
        geo = rho[rows] - np.linalg.norm(prev_sat[i_p] - r_ant, axis=1) \
            - (base[rows] - prev_base[i_p])
        y = sd[rows] - prev_sd[i_p] - geo
        a = np.column_stack([-los[rows] / rho[rows, None], np.ones(rows.size)])
        got = kern.tdcp_fit_rows(idx, slip, sd, prev_sd, init, rho, los, prev_sat, r_ant,
                                 base, prev_base)
        assert np.array_equal(got[0], rows)
        np.testing.assert_allclose(got[1], y, rtol=0, atol=1e-6)     # m, of ~1e7 m terms
        np.testing.assert_allclose(got[2], a, rtol=1e-12, atol=1e-15)
