"""Composite stochastic error models and their theoretical Haar wavelet variance.

A model is a tuple of process names from :data:`PROCESSES`, e.g. ``("WN", "AR1", "RW")``;
WN, QN, RW and DR appear at most once, AR1 any number of times (000 §3.3.5). Its
parameter vector ``theta`` lists each process' parameters in model order (sample units,
signal unit u, sample interval Δt):

=====  ===================  ==================================================================
WN     ``sigma2``           white-noise variance per sample, u²
QN     ``q2``               quantisation noise Q², u²;  X_t = Q (U_t − U_{t−1}), var U = 1
RW     ``gamma2``           random-walk innovation variance per sample, u²
DR     ``omega``            drift slope per sample, u (sign not identifiable: |ω| is used)
AR1    ``phi``, ``sigma2``  X_t = φ X_{t−1} + e_t, var e = sigma2 (innovation variance), u²
=====  ===================  ==================================================================

Theoretical Haar WV at scale τ_j = 2^j samples (000 Table 3.2, 002 eq. 28: the WV of a
sum of independent processes is the sum of their WVs):
WN σ²/τ, QN 6Q²/τ², RW γ²(τ²+2)/(12τ), DR ω²τ²/16, AR1 see :func:`ar1_wv`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import factorial

import numpy as np

PROCESSES = ("WN", "QN", "AR1", "RW", "DR")
PARAMETER_NAMES = {"WN": ("sigma2",), "QN": ("q2",), "RW": ("gamma2",), "DR": ("omega",),
                   "AR1": ("phi", "sigma2")}
_SERIES_TERMS = 10  # Taylor terms of 1 − φ^h in the AR1 WV when τ·(−ln φ) is small
_SERIES_LIMIT = 0.1  # switch to the closed form above τ/2·(−ln φ) = this


def check_model(model) -> tuple[str, ...]:
    """Validate a model (sequence of process names); returns it as a tuple."""
    model = tuple(str(p).upper() for p in model)
    if not model:
        raise ValueError("empty model")
    for p in model:
        if p not in PROCESSES:
            raise ValueError(f"unknown process {p!r}; known: {', '.join(PROCESSES)}")
    for p in ("WN", "QN", "RW", "DR"):
        if model.count(p) > 1:
            raise ValueError(f"{p} appears {model.count(p)} times; only AR1 may repeat")
    return model


def model_name(model) -> str:
    """``("WN","AR1","AR1","RW")`` → ``"WN+2*AR1+RW"`` (canonical order)."""
    model = canonical(model)
    parts = []
    for p in PROCESSES:
        n = model.count(p)
        if n:
            parts.append(p if n == 1 else f"{n}*{p}")
    return "+".join(parts)


def parse_model(text: str) -> tuple[str, ...]:
    """``"WN+QN+2*AR1+RW"`` or ``"WN+AR1+AR1"`` → a canonical model tuple."""
    out = []
    for token in text.replace(" ", "").split("+"):
        if not token:
            raise ValueError(f"empty term in model {text!r}")
        count, _, name = token.rpartition("*")
        n = int(count) if count else 1
        if n < 1:
            raise ValueError(f"bad count in {token!r}")
        out += [name] * n
    return canonical(out)


def canonical(model) -> tuple[str, ...]:
    model = check_model(model)
    return tuple(p for q in PROCESSES for p in model if p == q)


def n_params(model) -> int:
    return sum(len(PARAMETER_NAMES[p]) for p in model)


def parameter_labels(model) -> list[str]:
    """``["WN.sigma2", "AR1[1].phi", "AR1[1].sigma2", ...]`` in theta order."""
    labels, k = [], 0
    for p in model:
        tag = p
        if p == "AR1":
            k += 1
            tag = f"AR1[{k}]"
        labels += [f"{tag}.{name}" for name in PARAMETER_NAMES[p]]
    return labels


def split_theta(model, theta) -> list[np.ndarray]:
    """theta → one parameter array per process."""
    out, i = [], 0
    for p in model:
        n = len(PARAMETER_NAMES[p])
        out.append(np.asarray(theta[i:i + n], dtype=float))
        i += n
    return out


# ----------------------------------------------------------------------------- WV of each process

def wn_wv(sigma2, tau):
    return sigma2 / tau


def qn_wv(q2, tau):
    return 6.0 * q2 / tau ** 2


def rw_wv(gamma2, tau):
    return gamma2 * (tau ** 2 + 2.0) / (12.0 * tau)


def dr_wv(omega, tau):
    return omega ** 2 * tau ** 2 / 16.0


@lru_cache(maxsize=64)
def _haar_lag_moments(half: int) -> np.ndarray:
    """P_k = Σ_{h≥1} n_h h^k, k = 1.._SERIES_TERMS, with n_h the autocorrelation of the
    ±1 Haar pattern of length 2·half (n_h = 2(m−h)−h for h ≤ m, −(2m−h) above)."""
    m = half
    h = np.arange(1, 2 * m, dtype=float)
    n = np.where(h <= m, 2.0 * (m - h) - h, -(2.0 * m - h))
    return np.array([np.sum(n * h ** k) for k in range(1, _SERIES_TERMS + 1)])


_FACTORIALS = np.array([float(factorial(k)) for k in range(1, _SERIES_TERMS + 1)])
_POWERS = np.arange(1, _SERIES_TERMS + 1)
_SIGNS = (-1.0) ** (_POWERS + 1)


@lru_cache(maxsize=256)
def _scale_constants(tau_bytes: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per scale τ (float64 bytes): half-length m, (2m)² and the rows P_k of
    :func:`_haar_lag_moments` (the same few scale sets recur in every GMWM fit)."""
    tau = np.frombuffer(tau_bytes, dtype=float)
    m = (np.rint(tau) // 2).astype(np.int64)
    moments = np.array([_haar_lag_moments(int(k)) for k in m]).reshape(m.size, -1)
    out = (m, (2.0 * m) ** 2, moments)
    for a in out:
        a.flags.writeable = False  # shared by every later call
    return out


def ar1_wv(phi: float, sigma2: float, tau: np.ndarray) -> np.ndarray:
    """Haar WV of an AR1 (000 Table 3.2, eq. 4.1), evaluated without the cancellation of
    that closed form when φ → 1: with the stationary variance s² = σ²/(1−φ²), the Haar
    coefficient variance is −(2s²/τ²) Σ_h n_h (1 − φ^h) (the Σ n_h = 0 part cancels
    exactly); for τ/2·(−ln φ) < 0.1 the sum is a Taylor series in −ln φ, above it the
    geometric closed form, which is then well conditioned. All scales at once (the GMWM's
    optimiser evaluates it ~10⁵ times per calibrated axis)."""
    tau = np.asarray(tau, dtype=float)
    if not 0.0 <= phi < 1.0:
        raise ValueError(f"AR1 phi must be in [0, 1), got {phi}")
    if phi == 0.0:
        return sigma2 / tau
    delta = -np.log(phi)
    s2 = sigma2 / -np.expm1(-2.0 * delta)
    m, L2, moments = _scale_constants(np.ascontiguousarray(tau).tobytes())
    out = np.empty_like(tau)
    series = m * delta < _SERIES_LIMIT
    if series.any():
        coef = _SIGNS * delta ** _POWERS / _FACTORIALS
        out[series] = -2.0 * s2 / L2[series] * (moments[series] @ coef)
    if not series.all():
        mc = m[~series].astype(float)
        eps = -np.expm1(-delta)  # 1 − φ
        g = -np.expm1(-mc * delta) / eps  # (1−φ^m)/(1−φ)
        var_s = (mc * (1.0 + phi) - 2.0 * phi * g) / eps
        out[~series] = 2.0 * s2 * (var_s - phi * g * g) / L2[~series]
    return out


def ar1_wv_closed_form(phi: float, sigma2: float, tau: np.ndarray) -> np.ndarray:
    """000 Table 3.2 verbatim (for tests; loses precision as φ → 1)."""
    tau = np.asarray(tau, dtype=float)
    num = (phi ** 2 - 1.0) * tau + 2.0 * phi * (-4.0 * phi ** (tau / 2) + phi ** tau + 3.0)
    return num * sigma2 / ((phi - 1.0) ** 3 * (1.0 + phi) * tau ** 2)


def process_wv(process: str, params, tau) -> np.ndarray:
    tau = np.asarray(tau, dtype=float)
    if process == "WN":
        return wn_wv(params[0], tau)
    if process == "QN":
        return qn_wv(params[0], tau)
    if process == "RW":
        return rw_wv(params[0], tau)
    if process == "DR":
        return dr_wv(params[0], tau)
    if process == "AR1":
        return ar1_wv(float(params[0]), float(params[1]), tau)
    raise ValueError(process)


def model_wv(model, theta, tau) -> np.ndarray:
    """ν(θ) = Σ_m ν_m(τ) (002 eq. 28)."""
    tau = np.asarray(tau, dtype=float)
    total = np.zeros_like(tau)
    for p, params in zip(model, split_theta(model, theta)):
        total += process_wv(p, params, tau)
    return total


def contributions(model, theta, tau) -> list[np.ndarray]:
    """Each process' WV, model order (the classic GMWM plot's dashed lines)."""
    return [process_wv(p, params, tau) for p, params in zip(model, split_theta(model, theta))]


# ----------------------------------------------------------------------------- simulation

@dataclass(frozen=True)
class Outliers:
    """Additive outliers: a fraction of samples gets ± scale·(signal σ) added."""
    fraction: float
    scale: float


def simulate(model, theta, n: int, rng: np.random.Generator) -> np.ndarray:
    """One realisation of the composite model, n samples (002 Table I state equations;
    AR1 started in its stationary distribution, RW at 0)."""
    from scipy.signal import lfilter

    model = check_model(model)
    x = np.zeros(n)
    for p, params in zip(model, split_theta(model, theta)):
        if p == "WN":
            x += np.sqrt(params[0]) * rng.standard_normal(n)
        elif p == "QN":
            u = np.sqrt(12.0) * (rng.random(n + 1) - 0.5)
            x += np.sqrt(params[0]) * np.diff(u)
        elif p == "RW":
            x += np.cumsum(np.sqrt(params[0]) * rng.standard_normal(n))
        elif p == "DR":
            x += params[0] * np.arange(1, n + 1)
        elif p == "AR1":
            phi, s2 = float(params[0]), float(params[1])
            e = np.sqrt(s2) * rng.standard_normal(n)
            x0 = rng.standard_normal() * np.sqrt(s2 / (1.0 - phi * phi))
            y, _ = lfilter([1.0], [1.0, -phi], e, zi=[phi * x0])
            x += y
    return x


def add_outliers(x: np.ndarray, outliers: Outliers, rng: np.random.Generator) -> np.ndarray:
    """x with ``fraction`` of its samples shifted by ±scale·std(diff(x))/√2."""
    y = x.copy()
    k = round(outliers.fraction * x.size)
    if k:
        idx = rng.choice(x.size, size=k, replace=False)
        level = outliers.scale * np.std(np.diff(x)) / np.sqrt(2.0)
        y[idx] += level * rng.choice([-1.0, 1.0], size=k)
    return y


def tau_seconds(phi: float, dt: float) -> float:
    """Gauss-Markov correlation time of an AR1: τ = −Δt / ln φ (002 Table I)."""
    return float(-dt / np.log(phi)) if 0.0 < phi < 1.0 else 0.0
