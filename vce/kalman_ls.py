"""Residuals and redundancy indices of one Kalman update seen as least squares
(001 eq. 2.7.13-2.7.23; Wang 1997).

One epoch's update is the LS adjustment of three observation groups with unknowns
u = [x_k, w_k]:

    l_x = Φ x̂_{k−1} = x_k − Λ w_k     cov Σ_x = Φ P_{k−1} Φᵀ   (predicted state)
    l_w = 0         = w_k              cov Q                     (process noise)
    l_z = z         = H x_k            cov R                     (measurements)

With d = z − H Φ x̂_{k−1} and D = R + H P⁻ Hᵀ, P⁻ = Σ_x + Λ Q Λᵀ, the residuals
(v = A û − l) and redundancy contributions need no inverse of P⁻ (docs/DESIGN.md):

    v_z = −R D⁻¹ d            r_z = diag(R D⁻¹)            (block: tr(R_g (D⁻¹)_gg))
    v_w = Q Λᵀ Hᵀ D⁻¹ d       r_w = diag(Q Λᵀ Hᵀ D⁻¹ H Λ)
    v_x = Σ_x Hᵀ D⁻¹ d        r_x = tr(Σ_x Hᵀ D⁻¹ H)

and r_z + r_w + r_x = m (the number of measurements). These numpy versions serve as the
reference for the numba loop (gmis.gmikf) and for correlated groups (DD GNSS, σ²·M).
"""

import numpy as np


def kalman_residuals_and_redundancy(d, h, sigma_x, lam, q, r):
    """Residuals and redundancy matrices diagonals for one update (dense numpy).

    Returns dict with v_z (m,), v_w (nw,), v_x (n,), r_z (m,) = diag(R D⁻¹)... as the
    per-observation redundancy for diagonal R, R_z (m×m) = R D⁻¹ for block traces,
    r_w (nw,), r_x (scalar)."""
    d = np.asarray(d, float)
    dmat = r + h @ (sigma_x + lam @ q @ lam.T) @ h.T
    dinv_d = np.linalg.solve(dmat, d)
    dinv_h = np.linalg.solve(dmat, h)
    redundancy_z = r @ np.linalg.inv(dmat)
    hl = h @ lam
    return {
        "v_z": -r @ dinv_d,
        "v_w": q @ hl.T @ dinv_d,
        "v_x": sigma_x @ h.T @ dinv_d,
        "R_z": redundancy_z,
        "r_z": np.diag(redundancy_z).copy(),
        "r_w": np.diag(q @ hl.T @ np.linalg.solve(dmat, hl)).copy(),
        "r_x": float(np.trace(sigma_x @ h.T @ dinv_h)),
    }


def block_redundancy(redundancy_z, groups):
    """Redundancy of correlated groups: tr of the diagonal blocks of R D⁻¹ (5.1.8-5.1.11
    for DD observables with covariance σ²·M). groups: list of index arrays."""
    return np.array([np.trace(redundancy_z[np.ix_(g, g)]) for g in groups])


def _stacked_problem(h, sigma_x, lam, q, r):
    """Design A ((n + nw + m) × (n + nw), unknowns x and w) and block-diagonal covariance
    of the observations [x⁻; 0; z] of the three-group LS problem of eq. 2.7.13."""
    n, nw, m = sigma_x.shape[0], q.shape[0], r.shape[0]
    a = np.zeros((n + nw + m, n + nw))
    a[:n, :n] = np.eye(n)
    a[:n, n:] = -lam
    a[n:n + nw, n:] = np.eye(nw)
    a[n + nw:, :n] = h
    cov = np.zeros((n + nw + m,) * 2)
    cov[:n, :n] = sigma_x
    cov[n:n + nw, n:n + nw] = q
    cov[n + nw:, n + nw:] = r
    return a, cov


def brute_force_least_squares(x_pred, z, h, sigma_x, lam, q, r):
    """Solve the three-group LS problem of eq. 2.7.13 directly (normal equations) and
    return residuals and per-group redundancy from Q_v P (testing reference)."""
    n, nw = sigma_x.shape[0], q.shape[0]
    a, cov = _stacked_problem(h, sigma_x, lam, q, r)
    ell = np.concatenate([x_pred, np.zeros(nw), z])
    weight = np.linalg.inv(cov)
    normal = a.T @ weight @ a
    u = np.linalg.solve(normal, a.T @ weight @ ell)
    v = a @ u - ell
    q_v = cov - a @ np.linalg.solve(normal, a.T)
    red = q_v @ weight
    return {
        "x": u[:n], "w": u[n:],
        "v_x": v[:n], "v_w": v[n:n + nw], "v_z": v[n + nw:],
        "R_all": red,
        "r_x": float(np.trace(red[:n, :n])),
        "r_w": np.diag(red[n:n + nw, n:n + nw]).copy(),
        "r_z": np.diag(red[n + nw:, n + nw:]).copy(),
        "R_z": red[n + nw:, n + nw:],
    }


def helmert_matrix_elementary(d, h, sigma_x, lam, q, r):
    """Helmert's S_ij = tr(W Q_v W T_i W Q_v W T_j) for elementary components — every
    measurement (diagonal R) and every process-noise axis (diagonal Q) — of one update,
    computed from the LS structure: W Q_v W = Gᵀ D⁻¹ G with G = [−I, HΛ, H], so with
    C_i = G T_i Gᵀ (R_a e_a e_aᵀ or q_k h_k h_kᵀ) S_ij = tr(D⁻¹ C_i D⁻¹ C_j).
    Also returns q_i = dᵀ D⁻¹ C_i D⁻¹ d (= vᵀ W T_i W v) and r_i = tr(D⁻¹ C_i)."""
    dmat = r + h @ (sigma_x + lam @ q @ lam.T) @ h.T
    dinv = np.linalg.inv(dmat)
    hl = h @ lam
    cs = [np.outer(e, e) * r[a, a] for a, e in enumerate(np.eye(r.shape[0]))]
    cs += [np.outer(hl[:, k], hl[:, k]) * q[k, k] for k in range(q.shape[0])]
    s = np.array([[np.trace(dinv @ ci @ dinv @ cj) for cj in cs] for ci in cs])
    qv = np.array([d @ dinv @ ci @ dinv @ d for ci in cs])
    rr = np.array([np.trace(dinv @ ci) for ci in cs])
    return s, qv, rr


def brute_force_helmert_matrix(h, sigma_x, lam, q, r):
    """S_ij = tr(W Q_v W T_i W Q_v W T_j) straight from the stacked LS problem
    (testing reference for helmert_matrix_elementary)."""
    n, nw, m = sigma_x.shape[0], q.shape[0], r.shape[0]
    a, cov = _stacked_problem(h, sigma_x, lam, q, r)
    w = np.linalg.inv(cov)
    q_v = cov - a @ np.linalg.solve(a.T @ w @ a, a.T)
    wqw = w @ q_v @ w
    ts = []
    for i in range(m):
        t = np.zeros_like(cov)
        t[n + nw + i, n + nw + i] = r[i, i]
        ts.append(t)
    for k in range(nw):
        t = np.zeros_like(cov)
        t[n + k, n + k] = q[k, k]
        ts.append(t)
    return np.array([[np.trace(wqw @ ti @ wqw @ tj) for tj in ts] for ti in ts])
