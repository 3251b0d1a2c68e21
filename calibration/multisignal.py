"""Multi-signal estimators over K replicates of the same sensor (004, 000 §3.3.6, §4.4).

* AGMWM (000 eq. 3.25): the length-weighted mean of the per-replicate GMWM estimates;
  targets E[ϑ_i] (004 Theorem 1), not θ₀ when the WV is non-linear in θ (AR1).
* AWV (004 Algorithm 1, 000 eq. 3.26): GMWM on the weighted mean WV ν̄ = Σ w_i ν̂_i with
  Ω = Σ w_i Ω_i; consistent for θ₀ (004 Theorem 2). MS-GMWM (000 eq. 3.27) minimises
  Σ w_i ‖ν̂_i − ν(θ)‖²_Ω, which differs from the AWV objective by a constant (004
  Proposition 1): :func:`ms_gmwm` fits it directly as a check.
* SR-AWV / DR-AWV (000 eq. 4.10): AWV on robust WVs; DR also trims, per scale, the
  p = ⌊trim·K⌋ lowest and highest replicate WVs (weighted trimmed mean; the Ω_i of the
  kept replicates are averaged the same way).
Weights w_i = T_i / Σ T_j.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from calibration import gmwm as G
from calibration import processes as P
from calibration.wavelet_variance import WaveletVariance, chi2_interval, eta3


def _common_levels(wvs) -> int:
    return min(w.tau.size for w in wvs)


def replicate_weights(wvs) -> np.ndarray:
    n = np.array([w.n for w in wvs], dtype=float)
    return n / n.sum()


def average_wv(wvs: list[WaveletVariance], trim: float = 0.0) -> WaveletVariance:
    """ν̄ and its Ω: weighted (trimmed) mean per scale over the replicates."""
    J = _common_levels(wvs)
    w = replicate_weights(wvs)
    nu = np.array([x.nu2[:J] for x in wvs])  # (K, J)
    om = np.array([x.omega[:J] for x in wvs])
    K = len(wvs)
    p = int(np.floor(trim * K))
    if K - 2 * p < 1:
        raise ValueError(f"trim {trim} removes all {K} replicates")
    nu_bar, om_bar = np.empty(J), np.empty(J)
    for j in range(J):
        order = np.argsort(nu[:, j])
        keep = order[p:K - p]
        wk = w[keep] / w[keep].sum()
        nu_bar[j] = np.dot(wk, nu[keep, j])
        om_bar[j] = np.dot(wk, om[keep, j])
    variance = 1.0 / om_bar
    eta = 2.0 * nu_bar ** 2 / variance
    lo, hi = chi2_interval(nu_bar, eta, wvs[0].alpha)
    first = wvs[0]
    return WaveletVariance(first.tau[:J], nu_bar, lo, hi, variance, eta,
                           int(sum(x.n for x in wvs) / K), first.dt,
                           all(x.robust for x in wvs), first.alpha,
                           replicates=float(1.0 / np.sum(w ** 2) if p == 0 else K - 2 * p))


@dataclass
class MultiSignalResult:
    model: tuple[str, ...]
    awv: G.GmwmFit
    agmwm_theta: np.ndarray
    replicate_fits: list[G.GmwmFit]
    spread: np.ndarray  # between-replicate standard deviation of θ̂_i
    method: str  # "AWV", "SR-AWV" or "DR-AWV"


def agmwm(fits: list[G.GmwmFit], weights) -> np.ndarray:
    return np.sum(np.asarray(weights)[:, None] * np.array([f.theta for f in fits]), axis=0)


def multi_signal(wvs: list[WaveletVariance], model, trim: float = 0.0,
                 fit_replicates: bool = True) -> MultiSignalResult:
    """AWV fit (SR-AWV if the WVs are robust, DR-AWV if also trim > 0), the AGMWM and the
    between-replicate spread."""
    model = P.canonical(model)
    J = _common_levels(wvs)
    wvs = [w.select(np.arange(J)) for w in wvs]
    bar = average_wv(wvs, trim)
    awv = G.fit_gmwm(bar, model)
    fits = [G.fit_gmwm(w, model, extra_starts=[awv.theta]) for w in wvs] \
        if fit_replicates else []
    weights = replicate_weights(wvs)
    ag = agmwm(fits, weights) if fits else np.full(P.n_params(model), np.nan)
    spread = np.std([f.theta for f in fits], axis=0, ddof=1) if len(fits) > 1 else \
        np.full(P.n_params(model), np.nan)
    robust = all(w.robust for w in wvs)
    method = ("DR-AWV" if trim > 0 else "SR-AWV") if robust else "AWV"
    return MultiSignalResult(model, awv, ag, fits, spread, method)


def ms_gmwm(wvs: list[WaveletVariance], model, start) -> np.ndarray:
    """MS-GMWM: argmin Σ w_i ‖ν̂_i − ν(θ)‖²_Ω̄ (000 eq. 3.27), from ``start``."""
    model = P.canonical(model)
    J = _common_levels(wvs)
    bar = average_wv([w.select(np.arange(J)) for w in wvs])
    sw = np.sqrt(bar.omega)
    weights = np.sqrt(replicate_weights(wvs))
    nus = [w.nu2[:J] for w in wvs]

    def residuals(z):
        v = P.model_wv(model, G._from_z(model, z), bar.tau)
        return np.concatenate([wi * (nu - v) * sw for wi, nu in zip(weights, nus)])

    lo, hi = G._bounds(model, bar)
    z0 = np.clip(G._to_z(model, start), lo + 1e-9, hi - 1e-9)
    res = least_squares(residuals, z0, bounds=(lo, hi), x_scale="jac", xtol=1e-12,
                        ftol=1e-12, gtol=1e-12)
    return G._sort_ar1(model, G._from_z(model, res.x))


def near_stationary_omega(model, theta_draws, tau, n: int) -> np.ndarray:
    """diag Ω of the AWV as T → ∞ over replicates drawn from G: Σ w_i Ω_i with
    Ω_i = η₃(n, τ)/(2 ν(ϑ_i)²) (the χ² variance of
    :func:`calibration.wavelet_variance.wavelet_variance`, n samples per replicate),
    averaged over the rows of ``theta_draws`` (equal lengths)."""
    model = P.canonical(model)
    tau = np.asarray(tau, dtype=float)
    nus = np.array([P.model_wv(model, t, tau) for t in np.atleast_2d(theta_draws)])
    return np.mean(eta3(n, tau) / (2.0 * nus ** 2), axis=0)


def near_stationary_target(model, tau, nu_bar, omega, start) -> np.ndarray:
    """θ₀ of 004 eq. 4, argmin_θ E‖ν(ϑ) − ν(θ)‖²_Ω, for diagonal Ω (``omega``). The
    norm is quadratic, so E‖ν(ϑ) − ν(θ)‖²_Ω = E‖ν(ϑ) − ν̄‖²_Ω + ‖ν̄ − ν(θ)‖²_Ω with
    ν̄ = E[ν(ϑ)] (``nu_bar``): θ₀ is the fit of the model to the mean WV, from ``start``.
    The AWV targets θ₀ (004 Theorem 2), the AGMWM E[ϑ] (Theorem 1); they coincide when
    E[ν(ϑ)] = ν(E[ϑ]), e.g. when every parameter enters ν linearly (Proposition 3)."""
    model = P.canonical(model)
    tau = np.asarray(tau, dtype=float)
    sw = np.sqrt(np.asarray(omega, dtype=float))
    nu_bar = np.asarray(nu_bar, dtype=float)

    def residuals(z):
        return (nu_bar - P.model_wv(model, G._from_z(model, z), tau)) * sw

    res = least_squares(residuals, G._to_z(model, start), x_scale="jac", xtol=1e-15,
                        ftol=1e-15, gtol=1e-15)
    return G._sort_ar1(model, G._from_z(model, res.x))
