"""Overlapping Allan deviation (IEEE Std 952-1997, Annex C), vectorised with numpy.

For a rate signal y_k sampled every dt, with cluster size m (τ = m·dt) and the integrated
signal θ_k = dt·Σ_{i<k} y_i:

    σ²(τ) = 1 / (2 τ² (N − 2m)) · Σ_{k=0}^{N−2m−1} (θ_{k+2m} − 2 θ_{k+m} + θ_k)²

Slopes on a log-log plot: −1/2 for white rate noise (angle/velocity random walk, value at
τ = 1 s equals the density in unit/√s), +1/2 for rate random walk, 0 for bias instability.
"""

import numpy as np


def overlapping_allan_deviation(y, dt, taus=None, points=30):
    """σ(τ) of the samples y (N,) or (N, c) taken every dt seconds.

    taus: cluster times (s); default `points` log-spaced values from dt to N·dt/10, rounded
    to whole clusters. Returns (taus (K,), adev (K,) or (K, c))."""
    y = np.asarray(y, float)
    n = y.shape[0]
    if taus is None:
        m = np.unique(np.round(np.logspace(0, np.log10(max(n // 10, 1)), points)).astype(int))
    else:
        m = np.unique(np.maximum(np.round(np.asarray(taus, float) / dt).astype(int), 1))
    m = m[2 * m < n]
    theta = np.concatenate([np.zeros((1,) + y.shape[1:]), np.cumsum(y, axis=0) * dt])
    out = np.empty((m.size,) + y.shape[1:])
    for i, mi in enumerate(m):
        d = theta[2 * mi:] - 2.0 * theta[mi:-mi] + theta[:-2 * mi]
        out[i] = np.sqrt(np.mean(d * d, axis=0) / 2.0) / (mi * dt)
    return m * dt, out


def log_slope(taus, adev, tau_min, tau_max):
    """Least-squares slope of log σ against log τ over [tau_min, tau_max]."""
    sel = (taus >= tau_min) & (taus <= tau_max)
    return np.polyfit(np.log(taus[sel]), np.log(adev[sel]), 1)[0]
