"""LAMBDA integer least squares against an exhaustive reference search.

Reference ("brute force") search, independent of the LAMBDA factorisation/reduction/search:

* Box.  For any integer z with F(z) = (a - z)^T Q^{-1} (a - z) <= chi2, Cauchy-Schwarz gives
  (a_i - z_i)^2 = (e_i^T (a - z))^2 <= (e_i^T Q e_i) F(z) = Q_ii F(z), so z lies in the box
  |a_i - z_i| <= sqrt(chi2 Q_ii).  We take chi2 = the largest F of the m distinct integer
  vectors LAMBDA returned, evaluated here with Q^{-1}: m distinct integer vectors with F <= chi2
  exist, so the true m best all have F <= chi2 and lie inside the box.  If LAMBDA missed a
  better vector, that vector is inside the box and the comparison fails.
* Last coordinate.  For fixed values of the other n-1 coordinates, F is a convex parabola
  in z_l symmetric about its continuous minimiser c, so that slice's m best integers are
  among the 2m integers nearest c.  The global m best are each among the m best of their
  slice, so enumerating the (n-1)-dim box x those 2m integers is exhaustive.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gnss.lambda_ils import (
    LambdaInputError,
    decorrelate,
    ldl_decompose,
    partial_fix,
    ratio_test,
    resolve_integers,
    search,
)

LAMBDA_L1 = 299792458.0 / 1575.42e6
BOX_POINT_LIMIT = 3_000_000  # keeps the reference below ~1 s; generator is designed under it

HYP = settings(derandomize=True, deadline=None, max_examples=60, database=None,
               suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------- problem generators


def spectral_covariance(rng, n, log10_cond, sigma_max):
    """Random rotation of a spectrum with one tiny eigenvalue (cond = 10**log10_cond) and the
    others spread over one decade below sigma_max^2 [cycles^2]."""
    U, _ = np.linalg.qr(rng.normal(size=(n, n)))
    lam = sigma_max**2 * 10.0 ** (-rng.uniform(0.0, 1.0, size=n))
    lam[0] = sigma_max**2
    lam[-1] = sigma_max**2 / 10.0**log10_cond
    Q = U @ np.diag(lam) @ U.T
    return 0.5 * (Q + Q.T)


def gnss_like_covariance(rng, n, sigma_baseline_m, sigma_amb_cycles):
    """Float DD ambiguity covariance [cycles^2] of n+1 satellites (reference = highest):
    Q = G (sigma_b^2 I_3) G^T + sigma_a^2 C_DD, G rows (u_i - u_ref)/lambda_1 (baseline
    uncertainty projected on the DD line of sight), C_DD = I + 1 1^T the DD correlation."""
    az = rng.uniform(0.0, 2 * np.pi, size=n + 1)
    el = np.deg2rad(rng.uniform(10.0, 85.0, size=n + 1))
    u = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    ref = int(np.argmax(el))
    others = [i for i in range(n + 1) if i != ref]
    G = (u[others] - u[ref]) / LAMBDA_L1
    C_dd = np.eye(n) + np.ones((n, n))
    Q = sigma_baseline_m**2 * G @ G.T + sigma_amb_cycles**2 * C_dd
    return 0.5 * (Q + Q.T)


def float_ambiguities(rng, Q, offset_scale=20.0):
    """a = integer truth + N(0, Q) noise, truth drawn in [-offset_scale, offset_scale]."""
    n = Q.shape[0]
    truth = rng.integers(-offset_scale, offset_scale + 1, size=n)
    return truth + np.linalg.cholesky(Q) @ rng.normal(size=n)


# --------------------------------------------------------------------------- reference search


def quadratic_form(a, Q_inv, z):
    e = a[:, None] - np.asarray(z, dtype=float).reshape(a.size, -1)
    return np.einsum("in,ij,jn->n", e, Q_inv, e)


def brute_force_best(a, Q, chi2, m):
    """m best integer vectors of F(z) in the box of half-width sqrt(chi2 Q_ii) (module doc)."""
    n = a.size
    Q_inv = np.linalg.inv(Q)
    half = np.sqrt(chi2 * np.diag(Q)) + 1e-9
    lo = np.ceil(a - half).astype(np.int64)
    hi = np.floor(a + half).astype(np.int64)
    widths = hi - lo + 1
    last = int(np.argmax(widths))  # the widest coordinate is handled analytically
    pre = [i for i in range(n) if i != last]
    n_points = int(np.prod(widths[pre])) * 2 * m
    assert n_points <= BOX_POINT_LIMIT, f"reference box too large ({n_points} points)"
    grids = np.meshgrid(*[np.arange(lo[i], hi[i] + 1) for i in pre], indexing="ij")
    zp = np.column_stack([g.ravel() for g in grids]).astype(float)
    ep = a[pre][None, :] - zp
    P_ll = Q_inv[last, last]
    P_lp = Q_inv[last, pre]
    c = a[last] + ep @ P_lp / P_ll  # continuous minimiser of F over z_last per slice
    base = np.floor(c)
    best_z, best_f = [], []
    for off in range(-(m - 1), m + 1):
        zl = base + off
        el = a[last] - zl
        f = np.einsum("ki,ij,kj->k", ep, Q_inv[np.ix_(pre, pre)], ep) + 2 * el * (ep @ P_lp) \
            + P_ll * el**2
        z = np.empty((zp.shape[0], n))
        z[:, pre] = zp
        z[:, last] = zl
        best_z.append(z)
        best_f.append(f)
    Z_all = np.concatenate(best_z)
    F_all = np.concatenate(best_f)
    order = np.argsort(F_all)[:m]
    return Z_all[order].astype(np.int64), F_all[order], n_points


def assert_matches_brute_force(a, Q, res, m=2):
    Q_inv = np.linalg.inv(Q)
    cands = res.candidates[:, :m]
    assert len({tuple(c) for c in cands.T}) == m, "LAMBDA returned duplicate candidates"
    f_lambda = quadratic_form(a, Q_inv, cands)
    np.testing.assert_allclose(f_lambda, res.sq_norms[:m], rtol=1e-7, atol=1e-9)
    chi2 = float(np.max(f_lambda)) * (1 + 1e-9)
    z_ref, f_ref, _ = brute_force_best(a, Q, chi2, m)
    np.testing.assert_allclose(f_lambda, f_ref, rtol=1e-7, atol=1e-9)
    for k in range(m):
        np.testing.assert_array_equal(cands[:, k], z_ref[k])


# --------------------------------------------------------------------------- property tests


@HYP
@given(n=st.integers(2, 6), log10_cond=st.floats(0.0, 6.5), sigma_max=st.floats(0.1, 1.0),
       seed=st.integers(0, 2**32 - 1))
def test_best_two_equal_exhaustive_search_spectral(n, log10_cond, sigma_max, seed):
    rng = np.random.default_rng(seed)
    Q = spectral_covariance(rng, n, log10_cond, sigma_max)
    a = float_ambiguities(rng, Q)
    res = resolve_integers(a, Q)
    assert_matches_brute_force(a, Q, res)
    assert res.ratio == pytest.approx(res.sq_norm_second / res.sq_norm_best)


@HYP
@given(n=st.integers(2, 6), sigma_b=st.floats(0.01, 0.08), sigma_amb=st.floats(0.0005, 0.05),
       seed=st.integers(0, 2**32 - 1))
def test_best_two_equal_exhaustive_search_gnss_geometry(n, sigma_b, sigma_amb, seed):
    """cond(Q) reaches ~1e6 for n <= 4; for n = 5, 6 sigma_amb >= 0.005 (cond ~1e4) keeps the
    reference box (its volume grows like 1/sqrt(det Q)) within BOX_POINT_LIMIT."""
    if n >= 5:
        sigma_amb = max(sigma_amb, 0.005)
    rng = np.random.default_rng(seed)
    Q = gnss_like_covariance(rng, n, sigma_b, sigma_amb)
    a = float_ambiguities(rng, Q)
    assert_matches_brute_force(a, Q, resolve_integers(a, Q))


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
@pytest.mark.parametrize("log10_cond", [3.0, 6.0, 7.0])
def test_best_two_equal_exhaustive_search_ill_conditioned_grid(n, log10_cond):
    """Hypothesis' derandomised draws favour easy problems; this grid guarantees coverage of
    cond(Q) = 1e3 .. 1e7 for every n (5 seeded problems each, spectral generator)."""
    rng = np.random.default_rng(int(100 * n + 10 * log10_cond))
    for _ in range(5):
        Q = spectral_covariance(rng, n, log10_cond, 0.5)
        assert np.linalg.cond(Q) > 0.5 * 10**log10_cond
        a = float_ambiguities(rng, Q)
        assert_matches_brute_force(a, Q, resolve_integers(a, Q))


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_best_two_equal_exhaustive_search_gnss_grid(n):
    """DD-geometry covariances at the ill-conditioned end of the feasible range."""
    rng = np.random.default_rng(700 + n)
    sigma_amb = 0.0005 if n <= 4 else 0.005
    for _ in range(5):
        Q = gnss_like_covariance(rng, n, 0.08, sigma_amb)
        a = float_ambiguities(rng, Q)
        assert_matches_brute_force(a, Q, resolve_integers(a, Q))


@settings(derandomize=True, deadline=None, max_examples=25, database=None)
@given(n=st.integers(2, 5), seed=st.integers(0, 2**32 - 1))
def test_four_best_candidates_equal_exhaustive_search(n, seed):
    rng = np.random.default_rng(seed)
    Q = gnss_like_covariance(rng, n, 0.04, 0.03)
    a = float_ambiguities(rng, Q)
    res = resolve_integers(a, Q, n_cands=4)
    assert np.all(np.diff(res.sq_norms) >= 0)
    assert_matches_brute_force(a, Q, res, m=4)


def test_condition_numbers_reach_1e6_in_generators():
    """The property tests must really cover ill-conditioned problems (brief: cond >= 1e6)."""
    rng = np.random.default_rng(3)
    conds = [np.linalg.cond(spectral_covariance(rng, 6, 6.5, 0.5)) for _ in range(5)]
    assert min(conds) > 1e6
    rng = np.random.default_rng(4)
    conds = [np.linalg.cond(gnss_like_covariance(rng, 4, 0.08, 0.0005)) for _ in range(20)]
    assert np.median(conds) > 1e6
    conds = [np.linalg.cond(gnss_like_covariance(rng, 6, 0.08, 0.005)) for _ in range(20)]
    assert np.median(conds) > 1e4


@HYP
@given(n=st.integers(2, 8), gnss=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_reduction_is_unimodular_and_decorrelates(n, gnss, seed):
    rng = np.random.default_rng(seed)
    Q = (gnss_like_covariance(rng, n, 0.08, 0.005) if gnss
         else spectral_covariance(rng, n, rng.uniform(2.0, 6.0), 0.5))
    L, D = ldl_decompose(Q)
    np.testing.assert_allclose(L.T @ np.diag(D) @ L, Q, rtol=0, atol=1e-12 * np.abs(Q).max())
    Z, Lz, Dz = decorrelate(L, D)
    assert Z.dtype.kind == "i"
    assert round(abs(np.linalg.det(Z.astype(float)))) == 1
    Zf = Z.astype(float)
    Qz = Zf.T @ Q @ Zf
    np.testing.assert_allclose(Lz.T @ np.diag(Dz) @ Lz, Qz, rtol=0,
                               atol=1e-9 * np.abs(Qz).max())
    # LAMBDA reduction conditions: size-reduced L_z and no profitable adjacent swap left
    assert np.all(np.abs(np.tril(Lz, -1)) <= 0.5 + 1e-9)
    delta = Dz[:-1] + np.diag(Lz, -1) ** 2 * Dz[1:]
    assert np.all(delta >= Dz[1:] * (1 - 1e-8))
    # more diagonal: the product of the diagonal (>= det Q) moves towards det Q
    assert np.prod(np.diag(Qz)) <= np.prod(np.diag(Q)) * (1 + 1e-9)


def test_decorrelation_of_strongly_correlated_gnss_covariance():
    rng = np.random.default_rng(11)
    for _ in range(20):
        Q = gnss_like_covariance(rng, 8, 0.08, 0.005)
        Z, _, _ = decorrelate(*ldl_decompose(Q))
        Qz = Z.T.astype(float) @ Q @ Z.astype(float)
        assert np.linalg.cond(Qz) < np.linalg.cond(Q) / 100.0
        assert np.prod(np.diag(Qz)) < np.prod(np.diag(Q)) / 1e3


@HYP
@given(n=st.integers(2, 6), seed=st.integers(0, 2**32 - 1),
       shift=st.lists(st.integers(-10**6, 10**6), min_size=6, max_size=6))
def test_integer_shift_invariance(n, seed, shift):
    rng = np.random.default_rng(seed)
    Q = gnss_like_covariance(rng, n, 0.05, 0.02)
    a = float_ambiguities(rng, Q)
    k = np.array(shift[:n], dtype=np.int64)
    r0 = resolve_integers(a, Q)
    r1 = resolve_integers(a + k, Q)
    np.testing.assert_array_equal(r1.fixed, r0.fixed + k)
    np.testing.assert_array_equal(r1.second, r0.second + k)
    np.testing.assert_allclose([r1.sq_norm_best, r1.sq_norm_second],
                               [r0.sq_norm_best, r0.sq_norm_second], rtol=1e-6)


def test_search_on_diagonal_covariance_is_rounding():
    a = np.array([0.2, -1.7, 3.45])
    D = np.array([0.1, 0.2, 0.4])
    cands, s = search(a, np.eye(3), D, n_cands=3)
    np.testing.assert_array_equal(cands[:, 0], [0, -2, 3])
    # second best moves the coordinate with the cheapest extra cost: (0.55^2-0.45^2)/0.4 = 0.25
    np.testing.assert_array_equal(cands[:, 1], [0, -2, 4])
    np.testing.assert_allclose(s[0], 0.2**2 / 0.1 + 0.3**2 / 0.2 + 0.45**2 / 0.4)


# --------------------------------------------------------------------------- ratio test, partial fix


def test_ratio_test_accepts_precise_and_rejects_ambiguous_float():
    Q = np.diag([0.01, 0.01, 0.01])
    near = resolve_integers(np.array([3.02, -4.01, 7.03]), Q)
    np.testing.assert_array_equal(near.fixed, [3, -4, 7])
    assert ratio_test(near, 3.0)
    midway = resolve_integers(np.array([3.48, -4.01, 7.03]), Q)
    assert midway.ratio < 1.2
    assert not ratio_test(midway, 3.0)


def test_partial_fix_drops_the_poorly_determined_ambiguity():
    rng = np.random.default_rng(5)
    n = 7
    Q = 0.0004 * (np.eye(n) + np.ones((n, n)))  # sigma ~ 0.03 cycles, DD correlated
    Q[n - 1, n - 1] = 0.25  # one low-elevation satellite, sigma 0.5 cycles
    truth = rng.integers(-50, 50, size=n)
    a = truth + np.linalg.cholesky(Q) @ rng.normal(size=n)
    a[n - 1] = truth[n - 1] + 0.47  # deliberately ambiguous
    assert not ratio_test(resolve_integers(a, Q), 3.0)
    pf = partial_fix(a, Q, threshold=3.0, min_fixed=4)
    assert pf.passed
    np.testing.assert_array_equal(pf.fixed_mask, [True] * (n - 1) + [False])
    np.testing.assert_array_equal(pf.a_fixed[:n - 1], truth[:n - 1])
    # the free ambiguity is conditioned on the fixed ones, its fraction is not forced to integer
    assert abs(pf.a_fixed[n - 1] - np.rint(pf.a_fixed[n - 1])) > 0.05


def test_partial_fix_reports_failure_when_nothing_passes():
    Q = 0.09 * np.eye(4)
    a = np.array([0.5, 1.49, -2.5, 3.51])
    pf = partial_fix(a, Q, threshold=3.0, min_fixed=4)
    assert not pf.passed
    assert not pf.fixed_mask.any()
    np.testing.assert_array_equal(pf.a_fixed, a)


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "a, Q, message",
    [
        ([0.1, np.nan], np.eye(2), "a_float contains NaN"),
        ([0.1, 0.2], [[1.0, np.nan], [np.nan, 1.0]], "Q_a contains NaN"),
        ([0.1, 0.2], [[1.0, 0.5], [0.2, 1.0]], "not symmetric"),
        ([0.1, 0.2], [[1.0, 2.0], [2.0, 1.0]], "not positive definite"),
        ([0.1, 0.2], [[1.0, 1.0], [1.0, 1.0]], "not positive definite"),
        ([0.1, 0.2, 0.3], np.eye(2), "2x2 but there are 3"),
    ],
)
def test_bad_input_raises_value_error_with_message(a, Q, message):
    with pytest.raises(ValueError, match=message):
        resolve_integers(np.array(a), np.array(Q))
    with pytest.raises(LambdaInputError):
        resolve_integers(np.array(a), np.array(Q))


# --------------------------------------------------------------------------- success rate


def test_bootstrap_success_rate_matches_monte_carlo_bootstrapping_and_bounds_ils():
    """gnss.lambda_ils.bootstrap_success_rate (eq. PS) against an independent simulation:
    float errors e ~ N(0, Q) around the true integers 0, transformed with the LAMBDA Z,
    bootstrapped from the last ambiguity down with the conditional means built here from
    Q_z's blocks (Q_kS Q_SS⁻¹, not the L_z / D_z factors); the fraction of all-zero
    results must equal P_s within 4 binomial σ. The ILS (LAMBDA) success rate, counted on
    part of the samples, is at least the bootstrapping one (Teunissen 1999). 1-D: P_s =
    2Φ(1/(2σ)) − 1 exactly."""
    from scipy.stats import norm

    from gnss.lambda_ils import bootstrap_success_rate
    sigma = 0.2
    assert bootstrap_success_rate([[sigma ** 2]]) == pytest.approx(
        2.0 * norm.cdf(1.0 / (2.0 * sigma)) - 1.0, rel=1e-12)
    rng = np.random.default_rng(19)
    # a GNSS-like 3×3 and a strongly correlated 4×4 (cond 1e4), where the decorrelation
    # matters: the undecorrelated conditional variances would give P_s 0.23 instead of 0.70
    for q in (gnss_like_covariance(rng, 3, 0.02, 0.25),
              spectral_covariance(np.random.default_rng(5), 4, 4, 1.0)):
        n = q.shape[0]
        p_s = bootstrap_success_rate(q)
        assert 0.5 < p_s < 0.99, p_s           # a test that can tell P_s from 0 or 1
        z_mat = decorrelate(*ldl_decompose(q))[0].astype(float)
        qz = z_mat.T @ q @ z_mat
        samples = 100_000
        e = rng.multivariate_normal(np.zeros(n), q, size=samples)
        zh = e @ z_mat                                     # rows: (Zᵀ e)ᵀ
        zi = np.zeros_like(zh)
        for k in range(n - 1, -1, -1):
            rest = np.arange(k + 1, n)
            cond = zh[:, k].copy()
            if rest.size:
                gain = np.linalg.solve(qz[np.ix_(rest, rest)], qz[rest, k])
                cond -= (zh[:, rest] - zi[:, rest]) @ gain
            zi[:, k] = np.rint(cond)
        hits = np.all(zi == 0, axis=1)
        rate = hits.mean()
        assert abs(rate - p_s) < 4.0 * np.sqrt(p_s * (1 - p_s) / samples), (n, rate, p_s)
        ils = np.mean([np.all(resolve_integers(x, q).fixed == 0) for x in e[:1000]])
        assert ils >= p_s - 4.0 * np.sqrt(p_s * (1 - p_s) / 1000), (ils, p_s)
