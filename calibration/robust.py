"""Robust wavelet variance for the RGMWM (000 eqs. 3.23-3.24, Guerrier et al. 2022).

Per level, ν̃_j solves (1/M_j) Σ ψ(W_{j,t}/ν)² = a(c) with Tukey's biweight
ψ(r) = r ((r/c)² − 1)² for |r| ≤ c, 0 beyond; a(c) = E[ψ(Z)²], Z ~ N(0,1), makes it
consistent for Gaussian coefficients. Solved by the fixed point
ν²_{k+1} = (1/M_j) Σ ω(r)² W² / a, started at the MAD scale. c = 4.97 (60 % efficiency,
000 §3.3.5); the CIs use η₃ × efficiency degrees of freedom.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit
from scipy import integrate

from calibration.wavelet_variance import (
    WaveletVariance,
    eta3,
    haar_coefficients,
    n_scales,
    wavelet_variance_with_intervals,
)

TUKEY_C = 4.97


def _psi2(r, c):
    return np.where(np.abs(r) <= c, (r * ((r / c) ** 2 - 1.0) ** 2) ** 2, 0.0)


@lru_cache(maxsize=8)
def consistency_and_efficiency(c: float = TUKEY_C) -> tuple[float, float]:
    """a(c) = E[ψ(Z)²] and the Gaussian efficiency of the scale estimator relative to
    the classical one: var(ν̂²)/ν⁴ = 4 E[χ²]/E[χ'(Z)Z]² with χ = ψ² − a (classical: 2)."""
    pdf = lambda z: np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi)
    a = 2.0 * integrate.quad(lambda z: _psi2(z, c) * pdf(z), 0.0, c)[0]
    e_chi2 = 2.0 * integrate.quad(lambda z: (_psi2(z, c) - a) ** 2 * pdf(z), 0.0, c)[0] \
        + a * a * 2.0 * (1.0 - 0.5 * (1.0 + _erf(c / np.sqrt(2.0))))

    def dchi_z(z):
        h = 1e-6
        return (_psi2(z + h, c) - _psi2(z - h, c)) / (2.0 * h) * z

    e_dchi = 2.0 * integrate.quad(lambda z: dchi_z(z) * pdf(z), 0.0, c, limit=200)[0]
    var_rel = 4.0 * e_chi2 / e_dchi ** 2
    return float(a), float(2.0 / var_rel)


def _erf(x):
    from math import erf
    return erf(x)


@njit(cache=True)
def _biweight_scale2(w, c, a, v2, tol, max_iter):
    """Fixed point for ν² (allocation-free loop over the coefficients)."""
    n = w.size
    for _ in range(max_iter):
        v = np.sqrt(v2)
        s = 0.0
        for i in range(n):
            r = w[i] / v
            if abs(r) <= c:
                u = (r / c) ** 2 - 1.0
                s += u ** 4 * w[i] * w[i]
        if s == 0.0:   # every coefficient rejected: no robust scale, the classical one
            return np.mean(w * w)
        new = s / n / a
        if abs(new - v2) <= tol * v2:
            return new
        v2 = new
    return v2


def robust_wavelet_variance(x, dt: float = 1.0, levels: int | None = None,
                            alpha: float = 0.05, c: float = TUKEY_C) -> WaveletVariance:
    """Robust Haar WV (biweight M-estimator per level) with (1−α) CIs."""
    x = np.asarray(x, dtype=float)
    J = levels if levels is not None else n_scales(x.size)
    a, efficiency = consistency_and_efficiency(c)
    cum = np.concatenate(([0.0], np.cumsum(x - np.median(x))))
    tau = 2.0 ** np.arange(1, J + 1)
    nu2 = np.empty(J)
    for j in range(1, J + 1):
        w = np.ascontiguousarray(haar_coefficients(x, j, cum))
        # start at the MAD about 0 (ν² = E W², zero-mean coefficients): about the median it
        # collapses where few, overlapping coefficients of a RW share one sign (top levels)
        mad = np.median(np.abs(w)) / 0.6744897501960817
        v0 = max(mad * mad, 1e-300)
        nu2[j - 1] = _biweight_scale2(w, c, a, v0, 1e-10, 200)
    eta = eta3(x.size, tau) * efficiency
    return wavelet_variance_with_intervals(tau, nu2, eta, x.size, dt, True, alpha)
