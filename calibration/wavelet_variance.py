"""Haar MODWT wavelet variance (WV) and its confidence intervals (002 §III, 000 eq. 3.18).

Scales τ_j = 2^j samples, j = 1..J, J = ⌊log₂ N⌋ − 1 (000 §3.3.5). The MODWT Haar
coefficient ending at sample t is W_{j,t} = (Σ last τ/2 − Σ previous τ/2 samples)/τ_j,
formed from one cumulative sum, so every level costs a few vector operations. The
unbiased estimator is ν̂²_j = (1/M_j) Σ W²_{j,t} over the M_j = N − τ_j + 1 coefficients
that do not wrap around (002 eq. 9).

Confidence intervals: ν̂²_j η_j / ν²_j ~ χ²_{η_j} with η_j = max(M_j / 2^j, 1)
(Percival & Walden 2000, eq. 314c — the "η₃" approximation 000 §3.3.5 cites). The same
χ² law gives var(ν̂²_j) = 2 ν̂⁴_j / η_j, the diagonal covariance used for Ω (000 eq. 3.21).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2


@dataclass(frozen=True)
class WaveletVariance:
    """Empirical WV of one signal (units: signal unit squared)."""
    tau: np.ndarray  # (J,) scales in samples, 2^j
    nu2: np.ndarray  # (J,) WV estimate
    ci_low: np.ndarray  # (J,) lower bound of the CI
    ci_high: np.ndarray  # (J,) upper bound
    variance: np.ndarray  # (J,) var(ν̂²_j), for Ω
    eta: np.ndarray  # (J,) equivalent degrees of freedom (η₃ × efficiency)
    n: int  # samples
    dt: float  # sample interval, s
    robust: bool = False
    alpha: float = 0.05
    replicates: float = 1.0  # independent records averaged into ν̂ (AWV: 1/Σ w_i²)

    @property
    def tau_s(self) -> np.ndarray:
        return self.tau * self.dt

    @property
    def omega(self) -> np.ndarray:
        """Diagonal of the GMWM weight matrix Ω = V⁻¹ (000 eq. 3.21 up to a constant)."""
        return 1.0 / self.variance

    def select(self, keep: np.ndarray) -> WaveletVariance:
        keep = np.asarray(keep)
        return WaveletVariance(self.tau[keep], self.nu2[keep], self.ci_low[keep],
                               self.ci_high[keep], self.variance[keep], self.eta[keep],
                               self.n, self.dt, self.robust, self.alpha, self.replicates)


def n_scales(n: int) -> int:
    return max(int(np.floor(np.log2(n))) - 1, 1)


def haar_coefficients(x: np.ndarray, level: int, cumulative: np.ndarray | None = None):
    """MODWT Haar coefficients W_{j,t} of level j (τ = 2^j), the M_j = N − τ + 1
    non-boundary ones."""
    c = cumulative if cumulative is not None else np.concatenate(
        ([0.0], np.cumsum(np.asarray(x, dtype=float) - np.mean(x))))
    tau = 2 ** level
    m = tau // 2
    n = c.size - 1
    end = c[tau:n + 1]
    mid = c[m:n + 1 - m]
    start = c[0:n + 1 - tau]
    return (end - 2.0 * mid + start) / tau


def chi2_interval(nu2, eta, alpha=0.05):
    lo = eta * nu2 / chi2.ppf(1.0 - alpha / 2.0, eta)
    hi = eta * nu2 / chi2.ppf(alpha / 2.0, eta)
    return lo, hi


def eta3(n: int, tau: np.ndarray) -> np.ndarray:
    return np.maximum((n - tau + 1.0) / tau, 1.0)


def wavelet_variance(x, dt: float = 1.0, levels: int | None = None,
                     alpha: float = 0.05) -> WaveletVariance:
    """Classical (unbiased MODWT) Haar WV of ``x`` with (1−α) χ² CIs."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 8:
        raise ValueError("wavelet_variance needs a 1-D signal of at least 8 samples")
    J = levels if levels is not None else n_scales(x.size)
    c = np.concatenate(([0.0], np.cumsum(x - np.mean(x))))
    tau = 2.0 ** np.arange(1, J + 1)
    nu2 = np.empty(J)
    for j in range(1, J + 1):
        w = haar_coefficients(x, j, c)
        nu2[j - 1] = np.dot(w, w) / w.size
    eta = eta3(x.size, tau)
    return wavelet_variance_with_intervals(tau, nu2, eta, x.size, dt, False, alpha)


def wavelet_variance_with_intervals(tau, nu2, eta, n, dt, robust, alpha) -> WaveletVariance:
    """WaveletVariance from ν̂² (per scale τ) and its equivalent degrees of freedom η, with
    the χ²_η confidence interval at level 1 − alpha (002 §III); n samples at interval dt s."""
    lo, hi = chi2_interval(nu2, eta, alpha)
    variance = 2.0 * nu2 ** 2 / eta
    return WaveletVariance(tau, nu2, lo, hi, variance, eta, int(n), float(dt), robust, alpha)
