"""Overlapping Allan variance and its line-fit noise coefficients (000 §3.3.4, IEEE 952).

AV at cluster length m samples (τ = m Δt), maximal overlap (000 eq. 3.15):
σ²(τ) = 1/(2 m² (N − 2m + 1)) Σ_k (C_{k+2m} − 2C_{k+m} + C_k)², C the cumulative sum.
CI: σ̂² ν / σ² ~ χ²_ν with ν = N/m − 1, the χ² law whose ADEV relative error is 000 eq.
3.16's 1/√(2(N/m − 1)).

Line fits on log ADEV vs log τ with the slope fixed (000 Table 3.1, IEEE 952 Annex C):

===========  =====  =========================  ==============================
noise        slope  ADEV                        coefficient (unit)
===========  =====  =========================  ==============================
QN           −1     Q √3 / τ                    Q (u·s)
WN (ARW/VRW) −1/2   N / √τ                      N (u·√s)
BI           0      B √(2 ln 2 / π) (minimum)   B (u)
RRW          +1/2   K √(τ/3)                    K (u/√s)
rate ramp    +1     R τ / √2                    R (u/s)
===========  =====  =========================  ==============================

Each fit uses the longest run of consecutive τ whose local slope is within
``SLOPE_TOLERANCE`` of the nominal one; the bias instability is read at the ADEV minimum.
The τ range used is reported with every coefficient.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

SLOPE_TOLERANCE = 0.15
BI_FACTOR = np.sqrt(2.0 * np.log(2.0) / np.pi)  # 0.664
LINES = {  # name: (slope, ADEV = factor(τ) · coefficient)
    "quantization": (-1.0, lambda t: np.sqrt(3.0) / t),
    "random_walk": (-0.5, lambda t: 1.0 / np.sqrt(t)),
    "rate_random_walk": (0.5, lambda t: np.sqrt(t / 3.0)),
    "rate_ramp": (1.0, lambda t: t / np.sqrt(2.0)),
}


@dataclass(frozen=True)
class AllanVariance:
    tau_s: np.ndarray  # cluster times, s
    m: np.ndarray  # cluster lengths, samples
    avar: np.ndarray  # Allan variance, u²
    ci_low: np.ndarray  # (1−α) CI of the AV
    ci_high: np.ndarray
    edf: np.ndarray
    n: int
    dt: float

    @property
    def adev(self) -> np.ndarray:
        return np.sqrt(self.avar)


def cluster_lengths(n: int, per_octave: int = 1) -> np.ndarray:
    """m = 1, 2, 4, ... (per_octave points per octave, distinct integers) up to N/4."""
    top = np.log2(max(n // 4, 1))
    m = np.unique(np.round(2.0 ** np.arange(0.0, top + 1e-9, 1.0 / per_octave)).astype(int))
    return m[m >= 1]


def allan_variance(x, dt: float, m=None, alpha: float = 0.05) -> AllanVariance:
    """Maximal-overlap AV of the rate series ``x`` (u) sampled every ``dt`` s."""
    x = np.asarray(x, dtype=float)
    n = x.size
    m = cluster_lengths(n) if m is None else np.asarray(m, dtype=int)
    if np.any(m < 1) or np.any(2 * m > n - 1):
        raise ValueError("cluster lengths must satisfy 1 <= m <= (N-1)/2")
    c = np.concatenate(([0.0], np.cumsum(x - np.mean(x))))
    avar = np.empty(m.size)
    for i, mi in enumerate(m):
        d = c[2 * mi:] - 2.0 * c[mi:n + 1 - mi] + c[:n + 1 - 2 * mi]
        avar[i] = np.dot(d, d) / (2.0 * mi * mi * d.size)
    edf = np.maximum(n / m - 1.0, 1.0)
    lo = avar * edf / chi2.ppf(1.0 - alpha / 2.0, edf)
    hi = avar * edf / chi2.ppf(alpha / 2.0, edf)
    return AllanVariance(m * dt, m, avar, lo, hi, edf, n, float(dt))


@dataclass(frozen=True)
class LineFit:
    name: str
    coefficient: float  # see the module table for units
    tau_range_s: tuple[float, float]
    points: int


def _longest_run(ok: np.ndarray) -> tuple[int, int] | None:
    best, start = None, None
    for i, flag in enumerate(list(ok) + [False]):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            if best is None or i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    return best


def line_fits(tau_s, adev, edf=None, tau_max_s: float | None = None
              ) -> dict[str, LineFit | None]:
    """Noise coefficients from an ADEV curve (any implementation's): the fixed-slope
    line through the longest run of τ with matching local slope; BI at the minimum.
    ``tau_max_s`` limits the τ range used."""
    tau_s = np.asarray(tau_s, float)
    adev = np.asarray(adev, float)
    weights = np.ones_like(tau_s) if edf is None else np.asarray(edf, float)
    if tau_max_s is not None:
        keep = tau_s <= tau_max_s
        tau_s, adev, weights = tau_s[keep], adev[keep], weights[keep]
    lt, la = np.log(tau_s), np.log(adev)
    local = np.diff(la) / np.diff(lt)  # slope of segment i → (i, i+1)
    out: dict[str, LineFit | None] = {}
    for name, (slope, factor) in LINES.items():
        run = _longest_run(np.abs(local - slope) < SLOPE_TOLERANCE)
        if run is None:
            out[name] = None
            continue
        i0, i1 = run[0], run[1] + 1  # points of segments run[0]..run[1]-1
        idx = np.arange(i0, i1)
        w = weights[idx]
        log_coef = np.sum(w * (la[idx] - np.log(factor(tau_s[idx])))) / np.sum(w)
        out[name] = LineFit(name, float(np.exp(log_coef)),
                            (float(tau_s[i0]), float(tau_s[i1 - 1])), int(idx.size))
    k = int(np.argmin(adev))
    interior = 0 < k < adev.size - 1
    out["bias_instability"] = LineFit("bias_instability", float(adev[k] / BI_FACTOR),
                                      (float(tau_s[k]), float(tau_s[k])), 1) if interior \
        else None
    return out


def line_fits_of(av: AllanVariance, tau_max_s: float | None = None
                 ) -> dict[str, LineFit | None]:
    return line_fits(av.tau_s, av.adev, av.edf, tau_max_s)


def equivalent_white_sigma(arw, bias_instability, quantization, dt: float,
                           correlation_time_s: float = 100.0) -> float:
    """001 §5.3.2's one white-noise σ (u) at sample interval dt:
    √(σ_rw² + σ_bs² + σ_q²), σ_rw = N/√δt, σ_bs = B √(δt/T), σ_q = Q (T = 100 s)."""
    terms = [(arw or 0.0) / np.sqrt(dt),
             (bias_instability or 0.0) * np.sqrt(dt / correlation_time_s),
             quantization or 0.0]
    return float(np.sqrt(sum(t * t for t in terms)))
