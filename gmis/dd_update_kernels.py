"""Compiled pieces of the tightly coupled DD update (gmis.tc_filter) that run once per GNSS
epoch on matrices of a few dozen rows, where numpy's per-call overhead (~5-15 µs a call,
~40 calls) cost more than the arithmetic (issue 18: TC ≥ 40k IMU epochs/s).

- ``group_outlier_test``: the per-group test of 001 §5.2.3.1 (w_i = |d_i|/√D_ii against
  the normal critical value; without a single failure, d_gᵀ D_gg⁻¹ d_g against
  χ²(1 − α, n_g) rejects the group), as gmis.kalman_update_reference.group_outlier_test.
- ``group_vce_terms``: v = −R D⁻¹ d, vᵀR_g⁻¹v_g, r_g = tr(R_gg (D⁻¹)_gg) and the
  standardized residuals v_i/√(R D⁻¹ R)_ii (001 §5.2), as
  gmis.kalman_update_reference.group_vce_terms.
- ``satellite_statistics``: the one-fit per-satellite statistics T_k = u_kᵀ M_kk⁻¹ u_k of
  gmis.tc_filter.satellite_phase_test.

The numpy forms stay the readable references (gmis.kalman_update_reference,
tests/reference_tc_update.py); tests/test_dd_update_kernels.py holds these to them (the
same decisions, the figures to 1e-9 relative: LAPACK is called through scipy here and
through numpy there, so the last bits may differ)."""

from __future__ import annotations

import numpy as np
from numba import njit

from gmis.kalman_update_reference import GroupVceTerms


@njit(cache=True, error_model="numpy")
def _rows_of_group(groups, g):
    count = 0
    for i in range(groups.size):
        if groups[i] == g:
            count += 1
    idx = np.empty(count, np.int64)
    count = 0
    for i in range(groups.size):
        if groups[i] == g:
            idx[count] = i
            count += 1
    return idx


@njit(cache=True, error_model="numpy")
def _block(a, idx):
    out = np.empty((idx.size, idx.size))
    for i in range(idx.size):
        for j in range(idx.size):
            out[i, j] = a[idx[i], idx[j]]
    return out


@njit(cache=True, error_model="numpy")
def _outlier_kernel(d, s_mat, groups, n_groups, z_crit, chi2_crit):
    keep = np.ones(d.size, np.bool_)
    rejected = np.full(n_groups, -1, np.int64)          # −1: the group has no row
    for g in range(n_groups):
        idx = _rows_of_group(groups, g)
        if idx.size == 0:
            continue
        dg = d[idx]
        sg = _block(s_mat, idx)
        bad = np.empty(idx.size, np.bool_)
        any_bad = False
        for i in range(idx.size):
            bad[i] = abs(dg[i]) / np.sqrt(sg[i, i]) > z_crit
            any_bad = any_bad or bad[i]
        if not any_bad and dg @ np.linalg.solve(sg, dg) > chi2_crit[g]:
            bad[:] = True
        n_bad = 0
        for i in range(idx.size):
            if bad[i]:
                keep[idx[i]] = False
                n_bad += 1
        rejected[g] = n_bad
    return keep, rejected


def group_outlier_test(d, s_mat, groups, n_groups: int, crit):
    """Rows to keep (m,) bool and the number rejected per group present {g: n}. d (m,)
    innovations, s_mat (m, m) their covariance D, groups (m,) the group of each row
    (0 … n_groups − 1), crit an OutlierCriticalValues."""
    groups = np.ascontiguousarray(groups, dtype=np.int64)
    sizes = np.bincount(groups, minlength=n_groups)
    chi2_crit = np.array([crit.chi2(int(n)) if n else np.inf for n in sizes])
    keep, rejected = _outlier_kernel(np.ascontiguousarray(d, dtype=float),
                                     np.ascontiguousarray(s_mat, dtype=float), groups,
                                     n_groups, float(crit.z), chi2_crit)
    return keep, {g: int(n) for g, n in enumerate(rejected) if n >= 0}


@njit(cache=True, error_model="numpy")
def _vce_kernel(r_mat, dmat, dinv_d, groups, n_groups):
    m = dinv_d.size
    dinv = np.linalg.inv(dmat)
    v = -(r_mat @ dinv_d)
    vpv = np.zeros(n_groups)
    red = np.zeros(n_groups)
    n_obs = np.zeros(n_groups, np.int64)
    for g in range(n_groups):
        idx = _rows_of_group(groups, g)
        if idx.size == 0:
            continue
        rg = _block(r_mat, idx)
        vg = v[idx]
        vpv[g] = vg @ np.linalg.solve(rg, vg)
        tr = 0.0
        for a in range(idx.size):
            for b in range(idx.size):
                tr += rg[a, b] * dinv[idx[b], idx[a]]
        red[g] = tr
        n_obs[g] = idx.size
    rd = r_mat @ dinv
    standardized = np.empty(m)
    for i in range(m):
        q = 0.0
        for k in range(m):
            q += rd[i, k] * r_mat[k, i]
        standardized[i] = v[i] / np.sqrt(max(q, 1e-300))
    return vpv, red, n_obs, v, standardized


def group_vce_terms(r_mat, dmat, dinv_d, groups, n_groups: int) -> GroupVceTerms:
    """VCE terms of one update (module doc); groups (m,) the group of each row."""
    out = _vce_kernel(np.ascontiguousarray(r_mat, dtype=float),
                      np.ascontiguousarray(dmat, dtype=float),
                      np.ascontiguousarray(dinv_d, dtype=float),
                      np.ascontiguousarray(groups, dtype=np.int64), n_groups)
    return GroupVceTerms(*out)


@njit(cache=True, error_model="numpy")
def satellite_statistics(res, a_pos, r_mat, sat_k):
    """One weighted fit of the DD phase residuals res (m,) by a position correction
    (partials a_pos (m, 3), covariance r_mat (m, m)); per satellite of sat_k (m,):
    (sats sorted, n_rows, T_k = u_kᵀ M_kk⁻¹ u_k with u = R⁻¹v and M = R⁻¹ − R⁻¹A N⁻¹AᵀR⁻¹
    over its 1 or 2 rows, regular: that block is invertible, vᵀR⁻¹v of the fit).
    gmis.tc_filter.satellite_phase_test takes the irregular ones by an explicit refit."""
    m = res.size
    w = np.linalg.inv(r_mat)
    wa = w @ a_pos
    n_inv = np.linalg.pinv(np.ascontiguousarray(a_pos.T) @ wa)
    v = res - a_pos @ (n_inv @ (np.ascontiguousarray(wa.T) @ res))
    u = w @ v
    mm = w - wa @ n_inv @ np.ascontiguousarray(wa.T)
    sats = np.unique(sat_k)
    s = sats.size
    n_rows = np.zeros(s, np.int64)
    first = np.full(s, -1, np.int64)
    second = np.full(s, -1, np.int64)
    for i in range(m):
        k = np.searchsorted(sats, sat_k[i])
        if n_rows[k] == 0:
            first[k] = i
        elif n_rows[k] == 1:
            second[k] = i
        n_rows[k] += 1
    t_all = np.empty(s)
    regular = np.empty(s, np.bool_)
    for k in range(s):
        f = first[k]
        two = n_rows[k] == 2
        sc = second[k] if n_rows[k] > 1 else f
        m11, m22, m12 = mm[f, f], mm[sc, sc], mm[f, sc]
        u1, u2 = u[f], u[sc]
        if two:
            det = m11 * m22 - m12 ** 2
            regular[k] = det > 1e-8 * (m11 * m22)
            t_all[k] = (u1 ** 2 * m22 - 2.0 * u1 * u2 * m12 + u2 ** 2 * m11) / det
        else:
            regular[k] = n_rows[k] <= 2 and m11 > 1e-8 * w[f, f]
            t_all[k] = u1 ** 2 / m11
    return sats, n_rows, t_all, regular, v @ u


@njit(cache=True, error_model="numpy")
def tdcp_snooping_step(a, y):
    """One data-snooping step of the in-filter TDCP slip test (gmis.tc_filter
    TcFilter._tdcp_slip_test): the least-squares fit of y (n,) by a (n, 4) (unit weights),
    its residuals v = y − A N⁻¹Aᵀy and redundancy numbers r_i = 1 − a_i N⁻¹ a_iᵀ (≥ 1e-12);
    returns (i, v_i, r_i) of the row with the largest w_i = |v_i|/√r_i."""
    n_inv = np.linalg.inv(np.ascontiguousarray(a.T) @ a)
    v = y - a @ (n_inv @ (np.ascontiguousarray(a.T) @ y))
    best, best_w, best_r = 0, -1.0, 1.0
    for i in range(y.size):
        q = 0.0
        for j in range(a.shape[1]):
            for k in range(a.shape[1]):
                q += a[i, j] * n_inv[j, k] * a[i, k]
        r = max(1.0 - q, 1e-12)
        w = abs(v[i]) / np.sqrt(r)
        if w > best_w:
            best, best_w, best_r = i, w, r
    return best, v[best], best_r


@njit(cache=True, error_model="numpy")
def tdcp_fit_rows(idx, slip, sd, prev_sd, initialized, rho, los, prev_sat_pos, r_ant,
                  base_range, prev_base_range):
    """The rows of one frequency's TDCP slip-test fit (gmis.tc_filter
    TcFilter._tdcp_slip_test) and its data: satellites k present in the previous epoch
    (idx[k] ≥ 0), not flagged, with this frequency's SD phase at both epochs and an
    initialised ambiguity; y_k = Δ(SD Φ_k) − [|s_k(t) − r̂| − |s_k(t⁻) − r̂|] + Δρ_base,k (m)
    and the design rows [−e_kᵀ, 1] (e_k the unit line of sight). Returns (rows, y, a)."""
    n = idx.size
    take = np.zeros(n, np.bool_)
    count = 0
    for k in range(n):
        i = idx[k]
        if i >= 0 and not slip[k] and np.isfinite(sd[k]) and np.isfinite(prev_sd[i]) \
                and initialized[k]:
            take[k] = True
            count += 1
    rows = np.empty(count, np.int64)
    y = np.empty(count)
    a = np.empty((count, 4))
    c = 0
    for k in range(n):
        if not take[k]:
            continue
        i = idx[k]
        dx = prev_sat_pos[i, 0] - r_ant[0]
        dy = prev_sat_pos[i, 1] - r_ant[1]
        dz = prev_sat_pos[i, 2] - r_ant[2]
        geo = rho[k] - np.sqrt(dx * dx + dy * dy + dz * dz) \
            - (base_range[k] - prev_base_range[i])
        rows[c] = k
        y[c] = sd[k] - prev_sd[i] - geo
        for j in range(3):
            a[c, j] = -los[k, j] / rho[k]
        a[c, 3] = 1.0
        c += 1
    return rows, y, a
