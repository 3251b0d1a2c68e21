"""Generalized Method of Wavelet Moments (002 eq. 20, 000 eq. 3.20).

θ̂ = argmin (ν̂ − ν(θ))ᵀ Ω (ν̂ − ν(θ)), Ω = diag(1/var ν̂²_j) from the WV estimator's χ²
covariance (000 eq. 3.21 up to a constant factor, which does not move the minimum).

Parametrisation inside the optimiser: every variance (and the drift slope) as its log,
every AR1 φ as log τ_samples with φ = exp(−1/τ), so φ stays in (0, 1) and 0.9999 is as
easy as 0.5.

Guided initialisation (the idea of Balamuta et al. 2018, 000 §3.3.5): for a grid of AR1
correlation times spread over the scales, the WV is LINEAR in the amplitudes (σ²_WN, Q²,
γ², ω², ξ²_k), so each grid point is solved exactly by weighted non-negative least squares
(variable projection); the best few grid points start a bounded trust-region
least-squares fit of all parameters, and the lowest objective wins.

Standard errors: asymptotic, cov θ̂ = (DᵀΩD)⁻¹ DᵀΩVΩD (DᵀΩD)⁻¹ (delta method, D = ∂ν/∂θ)
with V the model-implied covariance of the WV estimator at θ̂ (calibration.wv_covariance:
between-scale correlations and the exact diagonal; ÷ the biweight's efficiency for a
robust WV); ``se="diagonal"`` takes V = Ω⁻¹ (the χ²(η₃) diagonal, which over-states the
variance of white-noise-dominated scales by ≈ 3 and ignores their correlation); or a
parametric bootstrap (refit on B series simulated from θ̂). Computed on the optimiser's
scale z (log variances, log τ) and mapped back, so the CIs stay inside the parameter space;
an amplitude whose natural-scale Wald test cannot exclude 0 gets the boundary-aware
interval [0, â + 1.96 se] instead (:func:`_boundary_intervals`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, nnls

from calibration import processes as P
from calibration.robust import consistency_and_efficiency
from calibration.wavelet_variance import WaveletVariance
from calibration.wv_covariance import wv_covariance

Z95 = 1.959963984540054
_GRID_POINTS = 20  # AR1 correlation-time candidates of the guided initialisation
_STARTS = 3  # best grid points refined by the full optimiser
_CDF_NODES = 256  # χ² quantile nodes of the boundary-aware interval's test


@dataclass
class GmwmFit:
    """A fitted composite model (sample units: variances per sample, u²)."""
    model: tuple[str, ...]
    theta: np.ndarray
    objective: float
    wv: WaveletVariance  # the empirical WV that was fitted (after scale selection)
    se: np.ndarray  # standard errors of theta
    ci_low: np.ndarray  # 95 % CI of theta (log/τ scale, mapped back)
    ci_high: np.ndarray
    se_method: str = "asymptotic (sandwich)"
    cov_z: np.ndarray | None = None  # covariance on the optimiser's scale
    n_evaluations: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def labels(self) -> list[str]:
        return P.parameter_labels(self.model)

    @property
    def name(self) -> str:
        return P.model_name(self.model)

    def model_parameter_is_drift(self, i: int) -> bool:
        return self.labels[i].startswith("DR.")

    def implied_wv(self, tau=None) -> np.ndarray:
        return P.model_wv(self.model, self.theta, self.wv.tau if tau is None else tau)

    def contributions(self, tau=None) -> list[np.ndarray]:
        return P.contributions(self.model, self.theta, self.wv.tau if tau is None else tau)

    def processes(self) -> list[dict]:
        """One dict per process: its parameters, their SEs and CIs; AR1s also get the
        Gauss-Markov τ (s) and stationary variance."""
        out, i, k = [], 0, 0
        dt = self.wv.dt
        for p in self.model:
            names = P.PARAMETER_NAMES[p]
            entry = {"process": p}
            if p == "AR1":
                k += 1
                entry["index"] = k
            for name in names:
                entry[name] = float(self.theta[i])
                entry[f"{name}_se"] = float(self.se[i])
                entry[f"{name}_ci95"] = [float(self.ci_low[i]), float(self.ci_high[i])]
                if self.labels[i] in self.extra.get("ci_at_bound", ()):
                    entry[f"{name}_ci95_at_bound"] = True
                i += 1
            if p == "AR1":
                phi, s2 = entry["phi"], entry["sigma2"]
                entry["tau_s"] = P.tau_seconds(phi, dt)
                lo, hi = entry["phi_ci95"]
                entry["tau_s_ci95"] = [P.tau_seconds(lo, dt), P.tau_seconds(hi, dt)]
                entry["stationary_variance"] = s2 / (1.0 - phi * phi)
            out.append(entry)
        return out


# ----------------------------------------------------------------------------- transforms

def _to_z(model, theta) -> np.ndarray:
    z, i = [], 0
    for p in model:
        if p == "AR1":
            phi, s2 = theta[i], theta[i + 1]
            z += [np.log(-1.0 / np.log(phi)), np.log(s2)]
            i += 2
        else:
            z.append(np.log(abs(theta[i])))
            i += 1
    return np.array(z, dtype=float)


def _from_z(model, z) -> np.ndarray:
    with np.errstate(over="ignore", divide="ignore"):
        return _from_z_raw(model, z)


def _from_z_raw(model, z) -> np.ndarray:
    theta, i = [], 0
    for p in model:
        if p == "AR1":
            theta += [np.exp(-1.0 / np.exp(z[i])), np.exp(z[i + 1])]
            i += 2
        else:
            theta.append(np.exp(z[i]))
            i += 1
    return np.array(theta, dtype=float)


def _dtheta_dz(model, theta) -> np.ndarray:
    g, i = [], 0
    for p in model:
        if p == "AR1":
            phi = theta[i]
            tau = -1.0 / np.log(phi)
            g += [phi / tau, theta[i + 1]]
            i += 2
        else:
            g.append(theta[i])
            i += 1
    return np.array(g)


# ----------------------------------------------------------------------------- initialisation

def _linear_columns(model, tau, ar1_taus) -> np.ndarray:
    """Columns of ν = A·amplitudes: WN 1/τ, QN 6/τ², RW (τ²+2)/(12τ), DR τ²/16 (for ω²),
    AR1 ν(φ_k, ξ²=1)."""
    cols, k = [], 0
    for p in model:
        if p == "WN":
            cols.append(P.wn_wv(1.0, tau))
        elif p == "QN":
            cols.append(P.qn_wv(1.0, tau))
        elif p == "RW":
            cols.append(P.rw_wv(1.0, tau))
        elif p == "DR":
            cols.append(P.dr_wv(1.0, tau))
        else:
            cols.append(P.ar1_wv(np.exp(-1.0 / ar1_taus[k]), 1.0, tau))
            k += 1
    return np.column_stack(cols)


def _amplitude_scale(model, tau, nu2, ar1_tau_default) -> np.ndarray:
    """Per process the amplitude that alone would explain ν̂ at its best scale."""
    A = _linear_columns(model, tau, [ar1_tau_default] * model.count("AR1"))
    return np.max(nu2[:, None] / A, axis=0)


def _theta_from_linear(model, amplitudes, ar1_taus, floor) -> np.ndarray:
    theta, k = [], 0
    for p, a, f in zip(model, amplitudes, floor):
        a = max(a, f)
        if p == "AR1":
            theta += [np.exp(-1.0 / ar1_taus[k]), a]
            k += 1
        elif p == "DR":
            theta.append(np.sqrt(a))
        else:
            theta.append(a)
    return np.array(theta)


def guided_starts(model, wv: WaveletVariance, n_starts: int = _STARTS) -> list[np.ndarray]:
    """Starting θ's: AR1 correlation times on a grid over the scales (distinct, sorted),
    amplitudes by weighted NNLS for each grid point; the n_starts best."""
    tau, nu2 = wv.tau, wv.nu2
    sw = np.sqrt(wv.omega)
    k = model.count("AR1")
    grid = np.geomspace(max(tau[0] / 8.0, 0.2), tau[-1] * 4.0, _GRID_POINTS)
    combos = list(itertools.combinations(grid, k)) if k else [()]
    scale = _amplitude_scale(model, tau, nu2, float(np.sqrt(tau[0] * tau[-1])))
    floor = 1e-8 * scale
    scored = []
    for combo in combos:
        A = _linear_columns(model, tau, combo) * sw[:, None]
        colnorm = np.linalg.norm(A, axis=0)
        amp, rnorm = nnls(A / colnorm, nu2 * sw)
        scored.append((rnorm, combo, amp / colnorm))
    scored.sort(key=lambda s: s[0])
    return [_theta_from_linear(model, amp, combo, floor)
            for _, combo, amp in scored[:n_starts]]


# ----------------------------------------------------------------------------- fit

def _bounds(model, wv: WaveletVariance):
    scale = _amplitude_scale(model, wv.tau, wv.nu2, float(np.sqrt(wv.tau[0] * wv.tau[-1])))
    lo, hi = [], []
    for p, s in zip(model, scale):
        s = np.sqrt(s) if p == "DR" else s
        if p == "AR1":
            lo += [np.log(0.05), np.log(s) - 60.0]
            hi += [np.log(wv.tau[-1] * 1e3), np.log(s) + 5.0]
        else:
            lo.append(np.log(s) - 60.0)
            hi.append(np.log(s) + 5.0)
    return np.array(lo), np.array(hi)


def _residual_fn(model, tau, nu2, sw):
    def residuals(z):
        return (nu2 - P.model_wv(model, _from_z(model, z), tau)) * sw
    return residuals


def _sort_ar1(model, theta) -> np.ndarray:
    """AR1 blocks in increasing φ (a label convention: AR1[1] is the fastest)."""
    blocks = P.split_theta(model, theta)
    ar = sorted([b for p, b in zip(model, blocks) if p == "AR1"], key=lambda b: b[0])
    out, k = [], 0
    for p, b in zip(model, blocks):
        if p == "AR1":
            out.append(ar[k])
            k += 1
        else:
            out.append(b)
    return np.concatenate(out)


def fit_gmwm(wv: WaveletVariance, model, start=None, scales=None,
             bootstrap: int = 0, rng: np.random.Generator | None = None,
             robust_wv=None, se: str = "sandwich", extra_starts=()) -> GmwmFit:
    """GMWM fit of ``model`` to the empirical WV ``wv``.

    ``start``: a θ (skips the guided grid, still refined); ``scales``: boolean mask or
    indices of the scales to use (000 §4.2 removes deviating scales); ``bootstrap``: B > 0
    gives parametric-bootstrap SEs (each replicate is simulated with wv.n samples and its
    WV computed like ``wv``: classical, or robust when wv.robust); ``se``: "sandwich"
    (model-implied V) or "diagonal" (V = Ω⁻¹) for the asymptotic standard errors, "none"
    for θ̂ and the objective only (SEs and CIs NaN; what model and scale selection use —
    the sandwich with its boundary-aware CIs is ≈ 60 % of a 3-AR1 fit's CPU);
    ``extra_starts``: θ's refined besides the guided ones (the AWV fit for a replicate:
    on a misspecified WV the guided starts alone can end with two AR1s at the same φ)."""
    if se not in ("sandwich", "diagonal", "none"):
        raise ValueError(f"se must be 'sandwich', 'diagonal' or 'none', got {se!r}")
    model = P.canonical(model)
    if scales is not None:
        wv = wv.select(scales)
    p = P.n_params(model)
    if wv.tau.size < p:
        raise ValueError(f"{P.model_name(model)} has {p} parameters but only "
                         f"{wv.tau.size} scales")
    sw = np.sqrt(wv.omega)
    fun = _residual_fn(model, wv.tau, wv.nu2, sw)
    lo, hi = _bounds(model, wv)
    starts = [np.asarray(start, float)] if start is not None else guided_starts(model, wv)
    starts += [np.asarray(t, float) for t in extra_starts]
    best, evaluations = None, 0
    for theta0 in starts:
        z0 = np.clip(_to_z(model, theta0), lo + 1e-9, hi - 1e-9)
        res = least_squares(fun, z0, bounds=(lo, hi), method="trf", x_scale="jac",
                            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400 * p)
        evaluations += res.nfev
        if best is None or res.cost < best.cost:
            best = res
    theta = _sort_ar1(model, _from_z(model, best.x))
    z = _to_z(model, theta)
    objective = float(np.sum(fun(z) ** 2))
    if se == "none":  # model selection, scale tests: θ̂ and the objective only
        nan = np.full(p, np.nan)
        return GmwmFit(model, theta, objective, wv, se=nan, ci_low=nan.copy(),
                       ci_high=nan.copy(), se_method="none", n_evaluations=evaluations)
    J = _jacobian(fun, z)
    cov_z = np.linalg.pinv(J.T @ J)
    extra = {"cov_z_diagonal": cov_z}  # V = Ω⁻¹ (for comparison in the benchmarks)
    if se == "sandwich" and set(model) == {"DR"}:
        se = "diagonal"  # a pure drift has no model-implied WV variance
    if se == "sandwich":
        V = wv_covariance(model, theta, wv.tau, wv.n, wv.replicates)
        if wv.robust:
            V = V / consistency_and_efficiency()[1]
        cov_z = cov_z @ (J.T @ (sw[:, None] * V * sw[None, :]) @ J) @ cov_z
    se_z = np.sqrt(np.maximum(np.diag(cov_z), 0.0))
    fit = GmwmFit(model, theta, objective, wv, se=se_z * _dtheta_dz(model, theta),
                  ci_low=_from_z(model, z - Z95 * se_z), ci_high=_from_z(model, z + Z95 * se_z),
                  se_method=f"asymptotic ({se})", cov_z=cov_z, n_evaluations=evaluations, extra=extra)
    _fix_phi_interval(fit, z, se_z)
    V_used = V if se == "sandwich" else None
    _boundary_intervals(fit, fun, sw, V_used)
    if bootstrap:
        _bootstrap(fit, bootstrap, rng or np.random.default_rng(0), robust_wv)
    return fit


def _fix_phi_interval(fit: GmwmFit, z, se_z) -> None:
    """φ = exp(−1/e^z) is increasing in z, so the mapped interval is already ordered;
    the amplitude and drift intervals likewise (exp). Nothing to swap — kept explicit."""
    assert np.all(fit.ci_low <= fit.ci_high + 1e-300)


def _amplitude_jacobian(fit: GmwmFit, fun, sw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residual Jacobian in the natural parametrisation u: every amplitude linear (σ², Q²,
    γ², ξ²_k, and ω² for the drift) and φ as log τ. ν is linear in each amplitude, so its
    column is exact, −ν_p(τ; amplitude 1)·√Ω, and stays non-zero at amplitude 0 (where the
    log-scale column vanishes). Returns (J_u, u, mask of the amplitudes)."""
    model, theta, tau = fit.model, fit.theta, fit.wv.tau
    z = _to_z(model, theta)
    cols, u, amp, i = [], [], [], 0
    for p in model:
        if p == "AR1":
            zp, zm = z.copy(), z.copy()
            h = 1e-6 * max(1.0, abs(z[i]))
            zp[i] += h
            zm[i] -= h
            cols.append((fun(zp) - fun(zm)) / (2.0 * h))
            cols.append(-P.ar1_wv(theta[i], 1.0, tau) * sw)
            u += [z[i], theta[i + 1]]
            amp += [False, True]
            i += 2
            continue
        if p == "DR":
            cols.append(-tau ** 2 / 16.0 * sw)
            u.append(theta[i] ** 2)
        else:
            cols.append(-P.process_wv(p, [1.0], tau) * sw)
            u.append(theta[i])
        amp.append(True)
        i += 1
    return np.column_stack(cols), np.array(u), np.array(amp)


def _boundary_intervals(fit: GmwmFit, fun, sw, V) -> None:
    """Boundary-aware 95 % CIs for the amplitudes (variances ≥ 0, 000 eq. 3.20's parameter
    space). The log-scale Wald interval cannot hold a small true amplitude once θ̂ sits at or
    next to 0: its width e^{±1.96 se_z} shrinks with θ̂ (on the WN+QN+2AR1+RW Monte Carlo
    18 of 60 fits put γ² at the bound and none of those CIs held the truth). Two simpler
    repairs fail (WN+AR1+RW, 2^15 samples, γ² = 1e-8, 40 fits): the natural-scale Wald
    interval [0, â + 1.96 se(θ̂)] covers 0.73 — se(θ̂) comes from the WV covariance V at θ̂,
    which lacks the very process whose amplitude is ≈ 0; inverting that test with se(a)
    taken under each hypothesised a covers, but is unbounded above in 39 of 40 fits (the
    top octaves that carry a RW have a few degrees of freedom: se(a)/a → 0.6 > 1/1.96).

    So each amplitude a gets its sandwich SE on the natural scale (J_u, linear columns),
    and when a two-sided test at 5 % at θ̂ cannot exclude a = 0 (â − 1.96 se_a ≤ 0) the CI
    is the inverted test {a ≥ 0 : |(â/a)^⅓ − (1 − r²/9)| ≤ 1.96 r/3}, r(a) = se(a)/a, with
    se²(a) the sandwich variance for V evaluated at θ̂ with that amplitude set to a: the
    Wilson-Hilferty normal approximation of a variance estimate â ~ a χ²_ν/ν, ν = 2/r²
    (the Gaussian Wald test on a when r is small). V is a quadratic in each amplitude
    (∫|H_j|²|H_k|²S² df, S linear in the amplitudes), so se²(a) = s₀ + s₁a + s₂a² from
    three V's. The interval starts at 0 when â is at the bound, and is unbounded above
    (ci_high = inf) only if the data cannot bound a (1 − s₂/9 ≤ 1.96 √s₂ / 3). Where 0 is
    excluded the log-scale interval stays (se ∝ a there: log a is the pivot)."""
    J_u, u, amp = _amplitude_jacobian(fit, fun, sw)
    scale = np.linalg.norm(J_u, axis=0)  # columns differ by 1e10 and more: equilibrate
    scale[scale == 0.0] = 1.0
    Js = J_u / scale
    bread = np.linalg.pinv(Js.T @ Js)
    R = (Js @ bread) / scale * sw[:, None]  # cov_u = Rᵀ V R (sandwich) / bread (diagonal)
    if V is None:
        cov_u = bread / np.outer(scale, scale)
    else:
        cov_u = R.T @ V @ R
    se_u = np.sqrt(np.maximum(np.diag(cov_u), 0.0))
    at_bound = amp & (u - Z95 * se_u <= 0.0)
    boundary = []
    for i in np.flatnonzero(at_bound):
        if V is None:
            s0, s1, s2 = se_u[i] ** 2, 0.0, 0.0
        else:
            s0, s1, s2 = _variance_quadratic(fit, i, R[:, i], u[i], cov_u[i, i], se_u[i])
        lo, hi = _inverted_test_interval(u[i], s0, s1, s2)
        if fit.model_parameter_is_drift(i):
            lo, hi = np.sqrt(lo), np.sqrt(hi)
        else:
            fit.se[i] = float(se_u[i])
        fit.ci_low[i], fit.ci_high[i] = lo, hi
        boundary.append(fit.labels[i])
    fit.extra["ci_at_bound"] = boundary
    fit.extra["se_natural"] = se_u


def _variance_quadratic(fit: GmwmFit, i: int, r: np.ndarray, a_hat: float,
                        var_hat: float, se_hat: float):
    """(s₀, s₁, s₂) with rᵀV(θ[a_i = a])r = s₀ + s₁a + s₂a² (exact: V quadratic in a),
    from V at θ̂ (known) and two more amplitudes."""
    def var_at(a):
        theta = fit.theta.copy()
        theta[i] = np.sqrt(a) if fit.model_parameter_is_drift(i) else a
        Va = wv_covariance(fit.model, theta, fit.wv.tau, fit.wv.n, fit.wv.replicates)
        if fit.wv.robust:
            Va = Va / consistency_and_efficiency()[1]
        return float(r @ Va @ r)

    if a_hat > 0.1 * se_hat:
        pts = [(a_hat, var_hat), (0.0, var_at(0.0)), (2.0 * a_hat, var_at(2.0 * a_hat))]
    else:  # at the bound: θ̂'s V is V at a ≈ 0
        pts = [(a_hat, var_hat), (se_hat, var_at(se_hat)), (2.0 * se_hat, var_at(2.0 * se_hat))]
    a, v = np.array(pts).T
    s2, s1, s0 = np.linalg.solve(np.vander(a, 3), v)
    return max(s0, 0.0), s1, max(s2, 0.0)


def _estimate_cdf(x: float, a: np.ndarray, s0: float, s1: float, s2: float) -> np.ndarray:
    """P(â ≤ x) under amplitude a (vector) for â = a·χ²_ν/ν + N(0, s₀ + s₁a), ν = 2/s₂:
    the amplitude's own part is a variance estimate (χ²-like, relative variance s₂), the
    rest — the other processes' share of the same scales — is Gaussian (it can push the
    unconstrained estimate below 0, the atom at the bound). Quantile quadrature of χ²_ν."""
    from scipy.stats import chi2, norm

    a = np.asarray(a, float)[:, None]
    sd_g = np.sqrt(np.maximum(s0 + s1 * a, 1e-300))
    if s2 <= 0.0:
        return norm.cdf((x - a) / sd_g)[:, 0]
    nu = 2.0 / s2
    q = chi2.ppf((np.arange(_CDF_NODES) + 0.5) / _CDF_NODES, nu)[None, :] / nu
    return np.mean(norm.cdf((x - a * q) / sd_g), axis=1)


def _inverted_test_interval(a_hat: float, s0: float, s1: float, s2: float):
    """{a ≥ 0 : 0.025 ≤ P_a(â ≤ a_hat) ≤ 0.975} (:func:`_estimate_cdf`) as (low, high);
    an â at the bound is the event â_unconstrained ≤ 0 and is tested as a_hat = 0."""
    a_hat = max(a_hat, 0.0)
    ref = max(a_hat, np.sqrt(max(s0 + s1 * a_hat + s2 * a_hat ** 2, 0.0)), 1e-300)
    grid = np.concatenate(([0.0], ref * np.geomspace(1e-6, 1e6, 1201)))
    F = _estimate_cdf(a_hat, grid, s0, s1, s2)
    inside = (F >= 0.025) & (F <= 0.975)
    if not inside.any():
        return 0.0, float(ref)  # cannot happen: a = â is accepted when s₀ > 0
    k0, k1 = np.flatnonzero(inside)[[0, -1]]
    lo = 0.0 if k0 == 0 else _edge(a_hat, grid[k0 - 1], grid[k0], s0, s1, s2)
    hi = np.inf if k1 == grid.size - 1 else _edge(a_hat, grid[k1], grid[k1 + 1], s0, s1, s2)
    return float(lo), float(hi)


def _edge(a_hat, a0, a1, s0, s1, s2) -> float:
    """The acceptance edge between a0 and a1 (one accepted, one not), by bisection on log a."""
    def ok(a):
        F = _estimate_cdf(a_hat, [a], s0, s1, s2)[0]
        return 0.025 <= F <= 0.975
    inside0 = ok(a0)
    for _ in range(40):
        m = np.sqrt(a0 * a1) if a0 > 0.0 else 0.5 * a1
        if ok(m) == inside0:
            a0 = m
        else:
            a1 = m
    return 0.5 * (a0 + a1)


def _jacobian(fun, z) -> np.ndarray:
    r0 = fun(z)
    J = np.empty((r0.size, z.size))
    for i in range(z.size):
        h = 1e-6 * max(1.0, abs(z[i]))
        zp, zm = z.copy(), z.copy()
        zp[i] += h
        zm[i] -= h
        J[:, i] = (fun(zp) - fun(zm)) / (2.0 * h)
    return J


def _bootstrap(fit: GmwmFit, B: int, rng, robust_wv) -> None:
    from calibration.robust import robust_wavelet_variance
    from calibration.wavelet_variance import wavelet_variance

    estimate = robust_wavelet_variance if fit.wv.robust else wavelet_variance
    zs = []
    levels = int(np.log2(fit.wv.tau[-1]))
    keep = np.isin(2.0 ** np.arange(1, levels + 1), fit.wv.tau)
    for _ in range(B):
        x = P.simulate(fit.model, fit.theta, fit.wv.n, rng)
        wv_b = estimate(x, fit.wv.dt, levels=levels).select(keep)
        fb = fit_gmwm(wv_b, fit.model, start=fit.theta, se="diagonal")
        zs.append(_to_z(fit.model, fb.theta))
    zs = np.array(zs)
    z = _to_z(fit.model, fit.theta)
    se_z = np.std(zs, axis=0, ddof=1)
    fit.se = se_z * _dtheta_dz(fit.model, fit.theta)
    fit.ci_low = _from_z(fit.model, z - Z95 * se_z)
    fit.ci_high = _from_z(fit.model, z + Z95 * se_z)
    fit.cov_z = np.cov(zs.T).reshape(z.size, z.size)
    fit.se_method = f"parametric bootstrap (B={B})"
    fit.extra["ci_at_bound"] = []
