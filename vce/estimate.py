"""Helmert-type variance component estimates from the GMIKF's per-epoch records
(001 §2.7.2, §5.2.2-5.2.3; eq. 2.7.22-2.7.23).

For a component j with variance σ_j² (cofactor fixed), summed over the run:

    σ̂²_0j = Σ_k v_jᵀ R_j⁻¹ v_j / Σ_k r_j          (measurement components)
    σ̂²_0j = Σ_k v_w,j² / q_j   / Σ_k r_w,j         (process-noise components)

and the next iteration uses σ_j·sqrt(σ̂²_0j). Observations rejected by the outlier
tests did not enter the update; they are excluded and counted as blunders, and the
truncation this leaves in the quadratic forms is removed per component from the loop's
per-row weights (:func:`truncation_deficit`, gmis.gmikf.truncation_terms). Process
(dynamics) components skip stationary epochs. The regional F-test (001 §5.2.3.2) compares
σ̂² of epochs 1…k−s with the last window k−s+1…k, F = σ̂²_g1/σ̂²_g2 ~ F(Σr_g1, Σr_g2),
at the end of every window of the run (:func:`regional_f_scan`).
"""

from dataclasses import dataclass

import numpy as np
from scipy import stats

from gmis.gmikf import N_SLOTS
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
    f_fail_t: float = np.nan  # end time of the first window failing the regional F-test


def component_columns(rec, comp):
    """(v, r, R_ii, rejected) of a measurement component, (v_w, r_w, None, None) of a
    process-noise one: the (E, k) columns of its slots / axes (column-major, as numpy
    lays out rec.vz[:, idx])."""
    idx = list(comp.index)
    if comp.kind == "measurement":
        return rec.vz[:, idx], rec.rz[:, idx], rec.rvar[:, idx], rec.rejected[:, idx]
    return rec.vw[:, idx], rec.rw[:, idx], None, None


def _terms(rec: FilterRecords, comp, q_var, stationary):
    """Per-(epoch, index) vPv terms, redundancies and 'used' mask for one component."""
    return _terms_of(component_columns(rec, comp), comp, q_var, stationary)


def _terms_of(columns, comp, q_var, stationary):
    """_terms of the component's columns (component_columns; whole, or a block of epochs
    with stationary the same block's flags: vce.blockwise)."""
    idx = list(comp.index)
    v, r, rv, rejected = columns
    if comp.kind == "measurement":
        used = np.isfinite(r)
        vpv = np.where(used, v * v / np.where(used, rv, 1.0), 0.0)
        blunders = int(rejected.sum())
    else:
        # an epoch whose update does not see the noise (r_w = 0: the fix-error noise at
        # epochs without a position row, gmis.gnss_error_states) holds no observation of it
        used = np.isfinite(r) & (r > 0)
        if comp.dynamics and stationary is not None:
            used &= ~stationary[:, None]
        q = q_var[idx][None, :]
        vpv = np.where(used, v * v / q, 0.0)
        blunders = 0
    return vpv, np.where(used, r, 0.0), used, blunders


def regional_f_test(vpv_rows, r_rows, f_alpha=0.05, s=None):
    """001 §5.2.3.2: F = σ̂²_g1/σ̂²_g2 ~ F(Σr_g1, Σr_g2) between the rows 1…k−s (g1) and
    the last s rows k−s+1…k (g2) of a component, k = all rows; s defaults to the second
    half. Larger variance on top. Returns (F, F_crit, pass); NaN and pass when there are
    too few rows or too little redundancy."""
    n = vpv_rows.size
    if s is None:
        s = n - n // 2
    if n < 4 or not 0 < s < n:
        return np.nan, np.nan, True
    g1, g2 = slice(0, n - s), slice(n - s, None)
    r1, r2 = r_rows[g1].sum(), r_rows[g2].sum()
    if not (r1 > 1 and r2 > 1):
        return np.nan, np.nan, True
    s1, s2 = vpv_rows[g1].sum() / r1, vpv_rows[g2].sum() / r2
    if s1 >= s2:
        f_stat, f_crit = s1 / s2, stats.f.ppf(1 - f_alpha, r1, r2)
    else:
        f_stat, f_crit = s2 / s1, stats.f.ppf(1 - f_alpha, r2, r1)
    return float(f_stat), float(f_crit), bool(f_stat <= f_crit)


def regional_f_scan(vpv_rows, r_rows, t_rows, window_s=60.0, f_alpha=0.05):
    """The regional F-test of 001 §5.2.3.2 applied along the run: at every k that ends a
    window of window_s seconds, epochs 1…k−s against the last window k−s+1…k. Returns
    (F, F_crit, pass, t_fail) of the window with the largest F/F_crit (pass = every window
    passes; t_fail = end time of the first failing window, NaN if none)."""
    n = vpv_rows.size
    if n < 4:
        return np.nan, np.nan, True, np.nan
    cv, cr = np.cumsum(vpv_rows), np.cumsum(r_rows)
    edges = np.arange(t_rows[0] + window_s, t_rows[-1] + window_s, window_s)
    worst, t_fail = (np.nan, np.nan, True), np.nan
    ratio_worst = -np.inf
    k_prev = 0
    for t_end in edges:
        k = int(np.searchsorted(t_rows, t_end, side="right"))   # rows 0..k-1
        s = k - k_prev
        k_prev = k
        if s <= 0 or k - s < 1:
            continue
        r1, r2 = cr[k - s - 1], cr[k - 1] - cr[k - s - 1]
        if not (r1 > 1 and r2 > 1):
            continue
        s1, s2 = cv[k - s - 1] / r1, (cv[k - 1] - cv[k - s - 1]) / r2
        if not (s1 > 0 and s2 > 0):
            continue
        if s1 >= s2:
            f, crit = s1 / s2, stats.f.ppf(1 - f_alpha, r1, r2)
        else:
            f, crit = s2 / s1, stats.f.ppf(1 - f_alpha, r2, r1)
        if f > crit and np.isnan(t_fail):
            t_fail = float(t_rows[k - 1])
        if f / crit > ratio_worst:
            ratio_worst = f / crit
            worst = (float(f), float(crit), bool(f <= crit))
    return worst[0], worst[1], bool(np.isnan(t_fail)), t_fail


def truncation_deficit(outlier_alpha: float) -> float:
    """τ = 2cφ(c) of the two-sided z-test at level α (c = Φ⁻¹(1−α/2)); 0 when the tests
    are off. For z ~ N(0, 1): E[z² 1(|z| ≤ c)] = 1 − α − τ, so a kept tested innovation
    has E[z² | kept] = κ = 1 − τ/(1 − α) (0.9883 at α = 0.001, τ = 0.01170) and a rejected
    one E[z² | rejected] − 1 = τ/α. The quadratic forms of the Helmert estimate then
    satisfy, to first order in α (gmis.gmikf.truncation_terms; docs/DESIGN.md):

        E[Σ dᵀD⁻¹C_iD⁻¹d] = Σ r_i − τ w_i,       E[Σ dᵀD⁻¹d] = Σ m − τ w_d,

    with w_i, w_d accumulated by the loop (FilterRecords.helmert_trunc) over the kept
    tested rows only: rows the tests do not see (the IMU rows since they are no longer
    tested) lose nothing of their own and only gain the tails of the rejected rows they
    are correlated with."""
    if not outlier_alpha > 0:
        return 0.0
    c = stats.norm.ppf(1 - outlier_alpha / 2)
    return float(2.0 * c * stats.norm.pdf(c))


def truncation_factor(outlier_alpha: float) -> float:
    """κ = E[z² | |z| ≤ c] = 1 − τ/(1 − α) of one tested N(0, 1) innovation
    (:func:`truncation_deficit`); 1 when the tests are off."""
    return 1.0 - truncation_deficit(outlier_alpha) / (1.0 - outlier_alpha) \
        if outlier_alpha > 0 else 1.0


def elementary_indices(comp):
    """Entries of the loop's Helmert sums (helmert_s rows, helmert_trunc) of a component:
    its measurement slots, or N_SLOTS + its noise axes."""
    return list(comp.index) if comp.kind == "measurement" else \
        [N_SLOTS + k for k in comp.index]


def component_truncation_factor(rec, comp, sum_r, outlier_alpha) -> float:
    """κ_i = 1 − τ w_i / Σ r_i (:func:`truncation_deficit`): E[Σ vᵀPv] = κ_i Σ r_i at the
    true noise, so Σ vᵀPv / κ_i is the truncation-free quadratic form. 1 when the tests
    are off or the run has no truncation weights."""
    trunc = getattr(rec, "helmert_trunc", None)
    tau = truncation_deficit(outlier_alpha)
    if tau == 0.0 or trunc is None or trunc.size == 0 or not sum_r > 0:
        return 1.0
    return 1.0 - tau * float(trunc[elementary_indices(comp)].sum()) / sum_r


def corrected_totals(rec, outlier_alpha) -> np.ndarray:
    """[Σ dᵀD⁻¹d / κ_d, Σ m], κ_d = 1 − τ w_d / Σ m (:func:`truncation_deficit`): the
    totals of the joint solve (helmert_system) with the outlier-test truncation removed
    from Σ dᵀD⁻¹d, consistently with the components' Σ vᵀPv / κ_i, so that the
    predicted-state group's q_x = Σ dᵀD⁻¹d − Σ q_i carries no truncation either."""
    chi2_all, m_all = rec.helmert_totals[:2]
    trunc = getattr(rec, "helmert_trunc", None)
    tau = truncation_deficit(outlier_alpha)
    if tau == 0.0 or trunc is None or trunc.size == 0 or not m_all > 0:
        return np.array([chi2_all, m_all], float)
    return np.array([chi2_all / (1.0 - tau * float(trunc[-1]) / m_all), m_all], float)


def estimate_component(rec, comp, q_var, stationary=None, f_alpha=0.05, window_s=60.0,
                       outlier_alpha=0.0):
    """Σ vᵀPv, Σ r and σ̂²₀ of one component. Σ vᵀPv is divided by the component's
    truncation factor κ_i (:func:`component_truncation_factor`): the outlier tests shrink
    the quadratic forms of what they test (and, through rejected rows, inflate those of
    the rows correlated with them); κ_i says by how much for this component. Dynamics
    components exclude stationary epochs from Σ vᵀPv and Σ r, the weight w_i includes
    them (the noise there is scaled by static_q_scale², its weight is negligible).
    Spooled records (vce.spooled_records): vce.blockwise.estimate, the same bits block
    by block."""
    vpv, r, used, blunders = _terms(rec, comp, q_var, stationary)
    s_r = float(r.sum())
    vpv = vpv / component_truncation_factor(rec, comp, s_r, outlier_alpha)
    s_vpv, n = float(vpv.sum()), int(used.sum())
    sigma0_sq = s_vpv / s_r if s_r > 0 else np.nan
    rows = np.flatnonzero(used.any(axis=1))
    f_stat, f_crit, f_pass, t_fail = regional_f_scan(
        vpv[rows].sum(axis=1), r[rows].sum(axis=1), rec.t[rows], window_s, f_alpha)
    return ComponentEstimate(s_vpv, s_r, n, blunders, sigma0_sq,
                             s_r / n if n else 0.0, f_stat, f_crit, f_pass, t_fail)


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
    return _standardized_of(component_columns(rec, comp), rec.t, comp, q_var, stationary)


def _standardized_of(columns, t_epochs, comp, q_var, stationary=None):
    """_standardized_residuals of the component's columns (component_columns) at the
    epochs t_epochs (whole, or a block: vce.blockwise)."""
    idx = list(comp.index)
    v, r, rv, _ = columns
    if comp.kind == "measurement":
        ok = np.isfinite(r) & (r > 0)
        w = v[ok] / np.sqrt(rv[ok] * r[ok])
        t = np.broadcast_to(t_epochs[:, None], v.shape)[ok]
    else:
        ok = np.isfinite(r) & (r > 0)
        if comp.dynamics and stationary is not None:
            ok &= ~stationary[:, None]
        q = np.broadcast_to(q_var[idx][None, :], v.shape)
        w = v[ok] / np.sqrt(q[ok] * r[ok])
        t = np.broadcast_to(t_epochs[:, None], v.shape)[ok]
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


# ---- joint Helmert estimate with a precision criterion (001 §2.7.2, §5.2.1) ----------

ESTIMATOR_HELMERT = "helmert"        # joint solve of the well-determined components
ESTIMATOR_SIMPLIFIED = "simplified"  # σ̂²_0j = Σ vᵀPv / Σ r of the component alone
ESTIMATOR_HELD = "held"              # not estimated: σ kept (low redundancy, no data, ...)


@dataclass
class JointEstimate:
    """Per component: variance factor, estimator used and the 1σ precision of the factor
    (NaN where held). precision = σ̂²·sqrt(2 (S⁻¹)_jj) for the joint solve (001 §5.2.1:
    D(σ̂²) = 2σ₀⁴ S⁻¹), σ̂²·sqrt(2/Σr) for the simplified ratio (S zeroed off-diagonal);
    precision_joint = sqrt(2 (S⁻¹)_jj) of the full candidate system, the identifiability
    of the component when all candidates are solved together (NaN where not a candidate).
    dropped: candidate names that left the joint solve, in order, with the reason."""
    sigma0_sq: np.ndarray
    estimator: list
    precision: np.ndarray
    precision_joint: np.ndarray
    dropped: list
    condition: float


def helmert_system(helmert_s, helmert_totals, rows, estimates):
    """The Helmert normal matrix of the components (index lists ``rows`` into the loop's
    accumulated S of elementary components) plus a free factor for the predicted-state
    group x (C_x = D − Σ C_i): returns (S_full (k×k), s_jx (k,), s_xx, q (k,), q_x)."""
    s_full = np.array([[helmert_s[np.ix_(ra, rb)].sum() for rb in rows] for ra in rows])
    q = np.array([e.sum_vpv for e in estimates], float)
    r = np.array([e.sum_r for e in estimates], float)
    chi2_all, m_all = helmert_totals
    s_jx = r - s_full.sum(axis=1)
    s_xx = m_all - 2 * r.sum() + s_full.sum()
    q_x = chi2_all - q.sum()
    return s_full, s_jx, s_xx, q, q_x


def _solve_joint(s_full, s_jx, s_xx, q, q_x, e_idx, h_idx):
    """Solve for the factors of components e_idx (+ x), those of h_idx fixed at 1.
    Returns (factors (len e_idx,), relative 1σ sqrt(2 diag S⁻¹) (len e_idx,), cond)."""
    n = e_idx.size
    a = np.zeros((n + 1, n + 1))
    a[:n, :n] = s_full[np.ix_(e_idx, e_idx)]
    a[:n, n] = s_jx[e_idx]
    a[n, :n] = s_jx[e_idx]
    a[n, n] = s_xx
    rhs = np.r_[q[e_idx] - s_full[np.ix_(e_idx, h_idx)].sum(axis=1),
                q_x - s_jx[h_idx].sum()]
    try:
        cond = float(np.linalg.cond(a))
        inv = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.full(n, np.nan), np.full(n, np.inf), np.inf
    factors = inv @ rhs
    var = 2.0 * np.diag(inv)[:n]
    sd = np.where(var > 0, np.sqrt(np.abs(var)), np.inf)
    return factors[:n], sd, cond


def joint_helmert(helmert_s, helmert_totals, rows, estimates, candidate, names=None,
                  max_sd: float = 0.1, simplified_only=None) -> JointEstimate:
    """Helmert VCE solved jointly for the candidate components that the data determine.

    candidate: (k,) bool, components to estimate (others are held at factor 1).
    simplified_only: (k,) bool or None, candidates that do not enter the joint solve at
    all (held at 1 in it) and take the simplified ratio (vce.tune: those that left the
    joint solve in an earlier iteration of the same job). The joint
    system (with the free predicted-state factor, see :func:`helmert_system`) is solved;
    while some candidate's relative precision sqrt(2 (S⁻¹)_jj) exceeds max_sd, or its
    factor is not positive and finite, the worst-determined such candidate leaves the joint
    solve (held at 1 in it) and is estimated by the simplified ratio Σ vᵀPv / Σ r instead.
    Every choice is returned per component (JointEstimate.estimator / dropped)."""
    k = len(estimates)
    names = names or [str(j) for j in range(k)]
    s_full, s_jx, s_xx, q, q_x = helmert_system(helmert_s, helmert_totals, rows, estimates)
    candidate = np.asarray(candidate, bool)
    sigma0 = np.full(k, np.nan)
    prec = np.full(k, np.nan)
    prec_joint = np.full(k, np.nan)
    estimator = [ESTIMATOR_HELD] * k
    dropped = []
    outside = (np.zeros(k, bool) if simplified_only is None
               else np.asarray(simplified_only, bool))
    cond = np.nan
    every = np.flatnonzero(candidate)     # the precision every candidate would have jointly
    if every.size:
        _, sd_all, cond = _solve_joint(s_full, s_jx, s_xx, q, q_x, every,
                                       np.flatnonzero(~candidate))
        prec_joint[every] = sd_all
    joint = np.flatnonzero(candidate & ~outside)
    while joint.size:
        held = np.setdiff1d(np.arange(k), joint)
        f, sd, cond = _solve_joint(s_full, s_jx, s_xx, q, q_x, joint, held)
        bad = ~np.isfinite(f) | (f <= 0) | (sd > max_sd)
        if not bad.any():
            sigma0[joint] = f
            prec[joint] = f * sd
            for j in joint:
                estimator[j] = ESTIMATOR_HELMERT
            break
        worst = int(np.flatnonzero(bad)[np.argmax(np.where(bad, sd, -1.0)[bad])])
        j = int(joint[worst])
        reason = (f"precision {sd[worst]:.3g} > {max_sd:g}" if sd[worst] > max_sd
                  else f"factor {f[worst]:.3g}")
        dropped.append((names[j], reason))
        joint = np.delete(joint, worst)
    for j in np.flatnonzero(candidate):
        if estimator[j] == ESTIMATOR_HELD:
            est = estimates[j]
            sigma0[j] = est.sigma0_sq
            prec[j] = est.sigma0_sq * np.sqrt(2.0 / est.sum_r) if est.sum_r > 0 else np.inf
            estimator[j] = ESTIMATOR_SIMPLIFIED
    return JointEstimate(sigma0, estimator, prec, prec_joint, dropped, cond)
