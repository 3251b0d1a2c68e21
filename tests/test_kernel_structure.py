"""The block pattern gmis.gmikf.propagate_covariance relies on: every non-zero entry of
phi_dyn (gmis.system_model.transition_jacobians_into) lies inside the declared column
ranges of its row block, at random states and step lengths; and the block-sparse
propagation equals the dense Φ P Φᵀ."""

import numpy as np

from gmis import gmikf
from gmis.state import N_DYNAMIC
from gmis.system_model import transition_jacobians_into


def _phi_lam(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=27)
    x[9:11] *= 0.5                      # pitch, roll away from ±90°
    dt = rng.uniform(0.001, 0.5)
    phi = np.zeros((N_DYNAMIC, N_DYNAMIC))
    lam = np.zeros((N_DYNAMIC, 6))
    transition_jacobians_into(x, dt, phi, lam)
    return phi, lam


def _phi(seed):
    return _phi_lam(seed)[0]


def test_phi_dyn_non_zeros_lie_in_the_declared_blocks():
    allowed = np.zeros((N_DYNAMIC, N_DYNAMIC), bool)
    for i in range(N_DYNAMIC):
        b = i // 3
        allowed[i, gmikf.PHI_LO1[b]:gmikf.PHI_HI1[b]] = True
        allowed[i, gmikf.PHI_LO2[b]:gmikf.PHI_HI2[b]] = True
    seen = np.zeros_like(allowed)
    for seed in range(50):
        phi = _phi(seed)
        seen |= phi != 0.0
        assert not (phi[~allowed] != 0.0).any(), np.argwhere((phi != 0.0) & ~allowed)
    # the pattern is not wider than needed by more than the structural zeros inside blocks
    assert seen.sum() >= 0.75 * allowed.sum()


def test_lam_dyn_non_zeros_lie_in_the_declared_noise_columns():
    """add_process_noise sums Λ Q Λᵀ over [LAM_LO, LAM_HI) of each row block only."""
    allowed = np.zeros((N_DYNAMIC, 6), bool)
    for i in range(N_DYNAMIC):
        allowed[i, gmikf.LAM_LO[i // 3]:gmikf.LAM_HI[i // 3]] = True
    seen = np.zeros_like(allowed)
    for seed in range(50):
        lam = _phi_lam(seed)[1]
        seen |= lam != 0.0
        assert not (lam[~allowed] != 0.0).any(), np.argwhere((lam != 0.0) & ~allowed)
    # not wider than needed: every declared (row block, noise block) pair is used
    for b in range(N_DYNAMIC // 3):
        for c in range(2):
            if allowed[3 * b, 3 * c]:
                assert seen[3 * b:3 * b + 3, 3 * c:3 * c + 3].any(), (b, c)


def test_process_noise_is_the_dense_product():
    """The block-restricted Λ Q Λᵀ of add_process_noise equals the dense one bit for bit."""
    rng = np.random.default_rng(5)
    lam = _phi_lam(11)[1]
    q_var = rng.uniform(0.1, 2.0, size=18)
    got = np.zeros((27, 27))
    gmikf.add_process_noise(got, lam, q_var, 27)
    full = np.zeros((27, 18))
    full[:N_DYNAMIC, :6] = lam
    full[N_DYNAMIC:, 6:] = np.eye(12)
    expect = np.zeros((27, 27))
    for i in range(27):               # the dense sum in index order, as the kernel had it
        for j in range(i, 27):
            for k in range(18):
                expect[i, j] += full[i, k] * q_var[k] * full[j, k]
            expect[j, i] = expect[i, j]
    assert np.array_equal(got, expect)


def test_block_sparse_propagation_is_the_dense_product():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(27, 27))
    p = a @ a.T
    p = 0.5 * (p + p.T)
    phi_dyn = _phi(9)
    phi = np.eye(27)
    phi[:N_DYNAMIC, :N_DYNAMIC] = phi_dyn
    expect = phi @ p @ phi.T
    got = p.copy()
    gmikf.propagate_covariance(got, 27, phi_dyn, np.zeros((N_DYNAMIC, 27)))
    upper = np.triu(np.ones((27, 27), bool))
    upper[N_DYNAMIC:, :] = True                 # the random-walk rows are complete
    np.testing.assert_allclose(got[upper], expect[upper], rtol=1e-12, atol=1e-12)


def test_phi_dyn_identity_blocks():
    """propagate_covariance takes Φ_rr and Φ_ωω as exact identities (rows r, ω: only the
    diagonal 1 in their own block)."""
    for seed in range(50):
        phi = _phi(seed)
        np.testing.assert_array_equal(phi[0:3, 0:3], np.eye(3))
        np.testing.assert_array_equal(phi[12:15, :], np.eye(15)[12:15])


def test_block_sparse_propagation_is_the_dense_sum_bit_for_bit():
    """The upper triangle of the dynamic block and the dynamic rows beyond it equal the
    dense sums Σ_k Φ_ik P_kj, then Σ_k W_ik Φ_jk, in index order from 0.0."""
    rng = np.random.default_rng(7)
    a = rng.normal(size=(27, 27))
    p = a @ a.T
    p = 0.5 * (p + p.T)
    p[0, 5] = p[5, 0] = -0.0            # signed zeros as at the start of a run
    p[13, 2] = p[2, 13] = 0.0
    phi_dyn = _phi(3)
    work = np.zeros((N_DYNAMIC, 27))
    for i in range(N_DYNAMIC):
        for j in range(27):
            acc = 0.0
            for k in range(N_DYNAMIC):
                acc += phi_dyn[i, k] * p[k, j]
            work[i, j] = acc
    got = p.copy()
    gmikf.propagate_covariance(got, 27, phi_dyn, np.zeros((N_DYNAMIC, 27)))
    for i in range(N_DYNAMIC):
        for j in range(i, N_DYNAMIC):
            acc = 0.0
            for k in range(N_DYNAMIC):
                acc += work[i, k] * phi_dyn[j, k]
            assert got[i, j] == acc and np.signbit(got[i, j]) == np.signbit(acc), (i, j)
        for j in range(N_DYNAMIC, 27):
            assert got[i, j] == work[i, j] and got[j, i] == work[i, j], (i, j)


def test_rank_m_subtraction_is_the_row_by_row_sum_bit_for_bit():
    """_subtract_wtw (six rows of W per pass) equals P −= Wᵀ W summed one row of W at a
    time from 0.0, upper triangle mirrored, for every m the kernel meets."""
    rng = np.random.default_rng(8)
    for m in range(1, 24):
        w = rng.normal(size=(23, 27))
        a = rng.normal(size=(27, 27))
        p = a @ a.T
        expect = p.copy()
        for i in range(27):
            row = np.zeros(27)
            for r in range(m):
                for j in range(i, 27):
                    row[j] += w[r, i] * w[r, j]
            for j in range(i, 27):
                expect[i, j] -= row[j]
                expect[j, i] = expect[i, j]
        got = p.copy()
        gmikf._subtract_wtw(got, m, w, np.zeros(27), 27)
        np.testing.assert_array_equal(got, expect)


def test_six_row_gain_terms_are_the_row_by_row_loop_bit_for_bit():
    """_gain_terms_six (u = L⁻¹d, W = L⁻¹HP, x += Wᵀu column by column in registers)
    equals the general row-wise forward substitution of _kalman_update_n."""
    rng = np.random.default_rng(9)
    n, m = 27, 6
    a = rng.normal(size=(m, m))
    sl = np.zeros((23, 23))
    sl[:m, :m] = np.linalg.cholesky(a @ a.T + m * np.eye(m))
    hp = rng.normal(size=(23, n))
    d = rng.normal(size=23)
    x0 = rng.normal(size=n)
    w_ref, u_ref, x_ref = np.zeros((23, n)), np.zeros(23), x0.copy()
    for r in range(m):
        w_ref[r] = hp[r]
        acc = d[r]
        for b in range(r):
            acc -= sl[r, b] * u_ref[b]
            for j in range(n):
                w_ref[r, j] -= sl[r, b] * w_ref[b, j]
        u_ref[r] = acc / sl[r, r]
        w_ref[r] /= sl[r, r]
    for j in range(n):
        acc = 0.0
        for r in range(m):
            acc += w_ref[r, j] * u_ref[r]
        x_ref[j] += acc
    w, u, x = np.zeros((23, n)), np.zeros(23), x0.copy()
    gmikf._gain_terms_six(x, d, hp, sl, w, u, n)
    np.testing.assert_array_equal(w, w_ref)
    np.testing.assert_array_equal(u, u_ref)
    np.testing.assert_array_equal(x, x_ref)
