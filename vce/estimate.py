"""Helmert-type variance component estimates from the GMIKF's per-epoch records
(001 §2.7.2, §5.2.2-5.2.3; eq. 2.7.22-2.7.23).

For a component j with variance σ_j² (cofactor fixed), summed over the run:

    σ̂²_0j = Σ_k v_jᵀ R_j⁻¹ v_j / Σ_k r_j          (measurement components)
    σ̂²_0j = Σ_k v_w,j² / q_j   / Σ_k r_w,j         (process-noise components)

and the next iteration uses σ_j·sqrt(σ̂²_0j). Observations rejected by the outlier
tests did not enter the update; they are excluded and counted as blunders. Process
(dynamics) components skip stationary epochs. The regional F-test (001 §5.2.3.2) compares
σ̂² of the first and second half of the run: F = σ̂²_g1/σ̂²_g2 ~ F(Σr_g1, Σr_g2).
"""

from dataclasses import dataclass

import numpy as np
from scipy import stats

from gmis.run_filter import FilterRecords


@dataclass
class ComponentEstimate:
    sum_vpv: float           # Σ vᵀ R⁻¹ v (or v_w²/q)
    sum_r: float             # Σ redundancy
    n_obs: int               # observations that entered the update
    n_blunders: int          # observations rejected by the outlier tests
    sigma0_sq: float         # σ̂²_0 = sum_vpv / sum_r
    mean_redundancy: float   # sum_r / n_obs
    f_stat: float            # regional F-test statistic (≥ 1)
    f_crit: float            # its critical value at the test level
    f_pass: bool


def _terms(rec: FilterRecords, comp, q_var, stationary):
    """Per-(epoch, index) vPv terms, redundancies and 'used' mask for one component."""
    idx = list(comp.index)
    if comp.kind == "measurement":
        v = rec.vz[:, idx]
        r = rec.rz[:, idx]
        rv = rec.rvar[:, idx]
        used = np.isfinite(r)
        vpv = np.where(used, v * v / np.where(used, rv, 1.0), 0.0)
        blunders = int(rec.rejected[:, idx].sum())
    else:
        v = rec.vw[:, idx]
        r = rec.rw[:, idx]
        used = np.isfinite(r)
        if comp.dynamics and stationary is not None:
            used &= ~stationary[:, None]
        q = q_var[idx][None, :]
        vpv = np.where(used, v * v / q, 0.0)
        blunders = 0
    return vpv, np.where(used, r, 0.0), used, blunders


def regional_f_test(vpv_rows, r_rows, f_alpha=0.05):
    """001 §5.2.3.2: F = σ̂²_g1/σ̂²_g2 ~ F(Σr_g1, Σr_g2) between the first and second half
    of the rows that carry a component (larger variance on top). Returns (F, F_crit, pass);
    NaN and pass when there are too few rows or too little redundancy."""
    n = vpv_rows.size
    if n < 4:
        return np.nan, np.nan, True
    g1, g2 = slice(0, n // 2), slice(n // 2, None)
    r1, r2 = r_rows[g1].sum(), r_rows[g2].sum()
    if not (r1 > 1 and r2 > 1):
        return np.nan, np.nan, True
    s1, s2 = vpv_rows[g1].sum() / r1, vpv_rows[g2].sum() / r2
    if s1 >= s2:
        f_stat, f_crit = s1 / s2, stats.f.ppf(1 - f_alpha, r1, r2)
    else:
        f_stat, f_crit = s2 / s1, stats.f.ppf(1 - f_alpha, r2, r1)
    return float(f_stat), float(f_crit), bool(f_stat <= f_crit)


def estimate_component(rec, comp, q_var, stationary=None, f_alpha=0.05):
    vpv, r, used, blunders = _terms(rec, comp, q_var, stationary)
    s_vpv, s_r, n = float(vpv.sum()), float(r.sum()), int(used.sum())
    sigma0_sq = s_vpv / s_r if s_r > 0 else np.nan
    rows = np.flatnonzero(used.any(axis=1))
    f_stat, f_crit, f_pass = regional_f_test(vpv[rows].sum(axis=1), r[rows].sum(axis=1),
                                             f_alpha)
    return ComponentEstimate(s_vpv, s_r, n, blunders, sigma0_sq,
                             s_r / n if n else 0.0, f_stat, f_crit, f_pass)


def sliding_window_sigma0(rec, comp, q_var, window_s=60.0, stationary=None):
    if comp.kind == "dd":
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return _sliding_window_sigma0(rec, comp, q_var, window_s, stationary)


def _sliding_window_sigma0(rec, comp, q_var, window_s=60.0, stationary=None):
    """σ̂²_0 of one component over consecutive windows of window_s seconds:
    (window centre times, σ̂²_0, Σr) — shows noise that changes along the run."""
    vpv, r, _, _ = _terms(rec, comp, q_var, stationary)
    t = rec.t
    edges = np.arange(t[0], t[-1] + window_s, window_s)
    k = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 2)
    s_vpv = np.bincount(k, vpv.sum(axis=1), minlength=edges.size - 1)
    s_r = np.bincount(k, r.sum(axis=1), minlength=edges.size - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sig = np.where(s_r > 0, s_vpv / s_r, np.nan)
    return edges[:-1] + window_s / 2, sig, s_r


def standardized_residuals(rec, comp, q_var, stationary=None, tc_rec=None):
    """(t, v/σ_v) of one component; DD groups come from the tightly coupled records
    (gmis.tc.TcRecords.residuals, σ_v² from Q_v = R D⁻¹ R of the correlated DD block)."""
    if comp.kind == "dd":
        if tc_rec is None or not tc_rec.residuals:
            return np.zeros(0), np.zeros(0)
        t, w = [], []
        for g, kinds, _, std in tc_rec.residuals:
            sel = kinds == comp.index[0]
            w.append(std[sel])
            t.append(np.full(int(sel.sum()), tc_rec.t[g]))
        return np.concatenate(t), np.concatenate(w)
    return _standardized_residuals(rec, comp, q_var, stationary)


def _standardized_residuals(rec, comp, q_var, stationary=None):
    """Standardized residuals of one component (all used observations, full rate):
    v / σ_v with σ_v² = R·r_z (measurements: Q_v = R D⁻¹ R) or q·r_w (process noise)."""
    idx = list(comp.index)
    if comp.kind == "measurement":
        v, r, rv = rec.vz[:, idx], rec.rz[:, idx], rec.rvar[:, idx]
        ok = np.isfinite(r) & (r > 0)
        w = v[ok] / np.sqrt(rv[ok] * r[ok])
        t = np.broadcast_to(rec.t[:, None], v.shape)[ok]
    else:
        v, r = rec.vw[:, idx], rec.rw[:, idx]
        ok = np.isfinite(r) & (r > 0)
        if comp.dynamics and stationary is not None:
            ok &= ~stationary[:, None]
        q = np.broadcast_to(q_var[idx][None, :], v.shape)
        w = v[ok] / np.sqrt(q[ok] * r[ok])
        t = np.broadcast_to(rec.t[:, None], v.shape)[ok]
    return t, w


def estimate_dd_component(tc_rec, comp, f_alpha=0.05):
    """σ̂²_0 of a tightly coupled DD group from the per-GNSS-epoch sums of gmis.tc
    (vᵀR⁻¹v with the correlated DD covariance, block redundancy tr(R_g (D⁻¹)_gg))."""
    g = comp.index[0]
    vpv, r, nobs = tc_rec.vpv[:, g], tc_rec.redundancy[:, g], tc_rec.n_obs[:, g]
    s_vpv, s_r, n = float(vpv.sum()), float(r.sum()), int(nobs.sum())
    sigma0_sq = s_vpv / s_r if s_r > 0 else np.nan
    rows = np.flatnonzero(nobs > 0)
    f_stat, f_crit, f_pass = regional_f_test(vpv[rows], r[rows], f_alpha)
    return ComponentEstimate(s_vpv, s_r, n, int(tc_rec.rejected_obs[:, g].sum()), sigma0_sq,
                             s_r / n if n else 0.0, f_stat, f_crit, f_pass)
