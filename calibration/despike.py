"""Time-domain despiking before the robust wavelet variance (Hampel identifier).

Why: an isolated additive outlier of size a is an outlier of the level-j Haar coefficients
only while 2^j is small; at level j it touches 2^j coefficients, and with a fraction f of
spikes the share of contaminated coefficients 1 − (1 − f)^(2^j) passes the biweight's 50 %
breakdown by j ≈ 7 for f = 1 %. There the spikes act, for any per-level estimator, like
extra white noise f·a², which the RGMWM's AR1/RW absorb (docs/DESIGN.md, "Robust WV
limits"). Spikes are found where they are large against the white noise — sample by
sample — and replaced before the WV:

    m_t = median(x_{t−k} … x_{t+k}),  r_t = x_t − m_t,  s = 1.4826 · median_t |r_t|
    x_t ← m_t  where |r_t| > n_sigma · s

(Hampel 1974; the global s, not a per-window MAD, so a window of 2k+1 samples does not
need to estimate a scale). For Gaussian data r_t has sd ≈ σ(1 + π/(4k+2))^½ and a
5-sigma threshold replaces ~6e-7 of the samples.
"""

from __future__ import annotations

import numpy as np
from numba import njit

HALF_WINDOW = 5
N_SIGMA = 5.0


@njit(cache=True)
def _running_median_residuals(x, k, res, med):
    n = x.size
    win = np.empty(2 * k + 1)
    for t in range(n):
        a = max(0, t - k)
        b = min(n, t + k + 1)
        m = b - a
        for i in range(m):
            win[i] = x[a + i]
        w = np.sort(win[:m])
        med[t] = w[m // 2] if m % 2 == 1 else 0.5 * (w[m // 2 - 1] + w[m // 2])
        res[t] = x[t] - med[t]


def despike(x, half_window: int = HALF_WINDOW, n_sigma: float = N_SIGMA):
    """(cleaned copy of x, number of samples replaced by their running median)."""
    x = np.ascontiguousarray(x, dtype=float)
    res = np.empty_like(x)
    med = np.empty_like(x)
    _running_median_residuals(x, int(half_window), res, med)
    s = 1.482602218505602 * np.median(np.abs(res))
    bad = np.abs(res) > n_sigma * s if s > 0 else np.zeros(x.size, bool)
    out = x.copy()
    out[bad] = med[bad]
    return out, int(bad.sum())
