"""The Kalman measurement update, the per-group outlier test and the VCE sums in plain
numpy: the reference the numba GMIKF kernel (gmis.gmikf) computes in its own loops, and
the implementation the tightly coupled DD update (gmis.tc_filter) uses directly.

Per measurement group g (rows idx_g of the innovation d = z − h(x⁻), D = H P Hᵀ + R):
- outlier test (001 §5.2.3.1): w_i = |d_i| / √D_ii against the two-sided normal
  critical value; if no single row fails, the group's χ² = d_gᵀ D_gg⁻¹ d_g against
  χ²(1 − α, n_g) rejects the whole group;
- update: K = P Hᵀ D⁻¹, x⁺ = x⁻ + K d, P⁺ = P⁻ − K H P⁻ (symmetrised);
- VCE terms (Helmert, 001 §5.2): v = −R D⁻¹ d, vᵀ R_g⁻¹ v_g and the redundancy
  r_g = tr(R_gg (D⁻¹)_gg), standardized residuals v_i / √(R D⁻¹ R)_ii.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gmis.critical_values import chi2_quantile, normal_quantile


@dataclass(frozen=True)
class OutlierCriticalValues:
    """Critical values of the outlier test at level alpha (α = 0 disables it): z (two-
    sided normal) and χ²(1 − α, dof) tabulated for dof ≤ table_dof (a quantile costs
    ~0.1 ms per call)."""
    alpha: float
    z: float
    chi2_table: np.ndarray

    @classmethod
    def at(cls, alpha: float, table_dof: int = 128) -> OutlierCriticalValues:
        dof = np.arange(1, table_dof + 1)
        if alpha > 0:
            return cls(alpha, float(normal_quantile(1 - alpha / 2)),
                       np.concatenate([[0.0], chi2_quantile(1 - alpha, dof)]))
        return cls(alpha, np.inf, np.full(dof.size + 1, np.inf))

    def chi2(self, dof: int) -> float:
        return chi2_critical(self.chi2_table, self.alpha, dof)


def chi2_critical(table, alpha: float, dof: int) -> float:
    """χ²(1 − alpha, dof) from a table (entry dof), computed beyond its end."""
    return table[dof] if dof < table.size else float(chi2_quantile(1 - alpha, dof))


def group_outlier_test(d, s_mat, group_rows: dict, crit: OutlierCriticalValues):
    """Rows to keep (m,) bool and the number rejected per group {g: n} (module doc).
    d (m,) innovations, s_mat (m, m) their covariance D, group_rows {g: row indices}."""
    keep = np.ones(d.size, bool)
    rejected = {}
    for g, idx in group_rows.items():
        dg = d[idx]
        sg = s_mat[np.ix_(idx, idx)]
        zstat = np.abs(dg) / np.sqrt(np.diag(sg))
        chi2 = dg @ np.linalg.solve(sg, dg)
        bad = zstat > crit.z
        if not bad.any() and chi2 > crit.chi2(idx.size):
            bad[:] = True
        keep[idx[bad]] = False
        rejected[g] = int(bad.sum())
    return keep, rejected


def kalman_update(x, p, h, d, r):
    """In place: x += K d, P −= K H P (symmetrised), K = P Hᵀ D⁻¹. Returns (D, D⁻¹ d)."""
    pht = p @ h.T
    dmat = h @ pht + r
    dinv_d = np.linalg.solve(dmat, d)
    gain = np.linalg.solve(dmat, pht.T).T
    x += gain @ d
    p -= gain @ pht.T
    p[:] = 0.5 * (p + p.T)
    return dmat, dinv_d


@dataclass
class GroupVceTerms:
    """Per group g < n_groups: vpv = v_gᵀ R_gg⁻¹ v_g, redundancy = tr(R_gg (D⁻¹)_gg), n_obs;
    v (m,) residuals −R D⁻¹ d and their standardized form v / σ_v."""
    vpv: np.ndarray
    redundancy: np.ndarray
    n_obs: np.ndarray
    v: np.ndarray
    standardized: np.ndarray


def group_vce_terms(r_mat, dmat, dinv_d, groups, n_groups: int) -> GroupVceTerms:
    """VCE terms of one update (module doc); groups (m,) the group of each row."""
    dinv = np.linalg.inv(dmat)
    v = -r_mat @ dinv_d
    vpv, red, n_obs = np.zeros(n_groups), np.zeros(n_groups), np.zeros(n_groups, int)
    for g in range(n_groups):
        idx = np.flatnonzero(groups == g)
        if idx.size == 0:
            continue
        rg = r_mat[np.ix_(idx, idx)]
        vpv[g] = v[idx] @ np.linalg.solve(rg, v[idx])
        red[g] = np.trace(rg @ dinv[np.ix_(idx, idx)])
        n_obs[g] = idx.size
    qv_diag = np.einsum("ij,jk,ki->i", r_mat, dinv, r_mat)
    return GroupVceTerms(vpv, red, n_obs, v, v / np.sqrt(np.maximum(qv_diag, 1e-300)))
