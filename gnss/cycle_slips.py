"""Cycle-slip detection on one satellite's arc (one receiver, GPS L1/L2).

Input is a ``SatelliteArc`` of per-epoch arrays (NaN = missing): time t [s], carrier phase
L1, L2 [cycles], code P1, P2 [m], Doppler D1 [Hz], loss-of-lock indicators (RINEX LLI).
Every detector returns a boolean flag per epoch, True meaning "a slip happened after the
previous valid epoch and at or before this one: the ambiguity must be reset here", and its
test statistic.  The first valid epoch of an arc is never flagged (the ambiguity is
initialised there, not reset).

Signal model (RINEX sign conventions, RINEX 3 §3: phase has the sign of the range,
Doppler is positive for approaching satellites):

    lambda_i L_i = rho - I_i + lambda_i N_i + eps_phi      I_2 = (f1/f2)^2 I_1
    P_i          = rho + I_i + eps_P
    D_1          = -d(L_1)/dt                               [Hz = cycles/s]

Detectors (each a function below; ``detect_cycle_slips`` combines them):

* geometry-free phase GF = lambda1 L1 - lambda2 L2 [m] = I_2 - I_1 + lambda1 N1 - lambda2 N2:
  geometry and clocks cancel; compared with a low-order polynomial prediction from the
  previous epochs of the same arc (order 0 = RTKLIB's epoch difference, ``detslp_gf``);
  threshold 0.05 m (RTKLIB ``thresslip``).  Blind to slips with lambda1 dN1 ~ lambda2 dN2,
  e.g. (dN1, dN2) = (9, 7) moves GF by 3.3 mm; (1, 1) moves it by 0.054 m, marginal.
* Melbourne-Wubbena MW = (L1 - L2) - (f1 P1 + f2 P2) / ((f1 + f2) lambda_WL) [WL cycles]
  = N1 - N2 + noise (geometry, clocks and first-order ionosphere cancel; Blewitt 1990).
  TurboEdit-style running mean/standard deviation over the last ``mw_window`` epochs since
  the last reset; slip when |MW - mean| > k sigma sqrt(1 + 1/n).  Blind to dN1 = dN2.
* Doppler-predicted phase: L1(k) - L1(k-1) + (D1(k) + D1(k-1))/2 dt [cycles] ~ 0 (the
  trapezoidal integral of dL1/dt = -D1), threshold a + b dt.  Sees L1 slips of any kind;
  blind to L2-only slips; only useful at high rates (the prediction error grows with dt).
* loss of lock: LLI bit 0 set on L1 or L2;
* data gap: more than ``max_gap_s`` since the previous valid phase of the same frequency.

Frequencies and wavelengths: GPS L1 1575.42 MHz, L2 1227.60 MHz, c = 299792458 m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from gnss.constants import C_LIGHT, FREQ_L1, FREQ_L2, WAVELENGTH_L1, WAVELENGTH_L2
from gnss.errors import GnssInputError

__all__ = [
    "C_LIGHT",
    "F_L1",
    "F_L2",
    "LAMBDA_L1",
    "LAMBDA_L2",
    "LAMBDA_WL",
    "DetectorResult",
    "SatelliteArc",
    "SlipConfig",
    "SlipInputError",
    "SlipReport",
    "data_gap_detector",
    "detect_cycle_slips",
    "doppler_phase_detector",
    "geometry_free",
    "geometry_free_detector",
    "loss_of_lock_detector",
    "melbourne_wubbena",
    "melbourne_wubbena_detector",
    "mw_prior_sigma_cycles",
]

F_L1 = FREQ_L1  # Hz
F_L2 = FREQ_L2  # Hz
LAMBDA_L1 = WAVELENGTH_L1  # 0.1903 m
LAMBDA_L2 = WAVELENGTH_L2  # 0.2442 m
LAMBDA_WL = C_LIGHT / (F_L1 - F_L2)  # 0.8619 m


class SlipInputError(GnssInputError, ValueError):
    """Bad arc or configuration for the cycle-slip detectors."""


@dataclass(frozen=True)
class SatelliteArc:
    """One satellite tracked by one receiver; all arrays (N,), NaN = missing.
    time [s] strictly increasing; L1, L2 [cycles]; P1, P2 [m]; D1 [Hz]; lli1, lli2 RINEX
    loss-of-lock indicators (ints, NaN or None = 0)."""

    time: np.ndarray
    L1: np.ndarray
    L2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    D1: np.ndarray
    lli1: np.ndarray | None = None
    lli2: np.ndarray | None = None


@dataclass(frozen=True)
class SlipConfig:
    """Detector settings.

    gf_threshold_m: |GF - predicted GF| limit [m] (RTKLIB thresslip 0.05 m).
    gf_poly_order: prediction polynomial order (0 = epoch difference as RTKLIB; 1 removes
        the ionospheric drift, which matters at 30 s sampling).
    gf_window: number of previous valid epochs (since the last reset) used for the fit.
    mw_k_sigma: k of the k-sigma test (TurboEdit uses 4).
    mw_window: maximum number of previous epochs in the running mean/std.
    code_sigma_m: code noise used for the MW prior sigma
        sigma_MW = code_sigma sqrt(f1^2 + f2^2) / (f1 + f2) / lambda_WL [WL cycles];
    mw_prior_weight: weight (in epochs) of that prior in the running variance, so a
        freshly reset arc is not tested against a standard deviation from 2-3 samples.
    mw_confirm: TurboEdit look-ahead: a candidate is a slip only if the next valid epoch
        also departs from the old mean, else it is an outlier (excluded from the statistics).
    doppler_base_cycles, doppler_rate_cycles_per_s: Doppler test threshold
        a + b dt [cycles]; defaults 0.5 + 0.25 dt: ~18 sigma at 1 Hz for 0.05 Hz Doppler noise
        and 3 mm phase noise, 8 cycles at 30 s.  Vehicle jerk j [m/s^3] adds a trapezoid error
        ~ j dt^3 / (12 lambda1): raise b for dynamic platforms.
    max_gap_s: longest allowed interval between valid phases [s]; None = 2 x the median
        epoch interval of the arc (one missing epoch is tolerated, two are not).
    lli_mask: LLI bits that mean loss of lock (bit 0 = 1, RINEX).
    """

    gf_threshold_m: float = 0.05
    gf_poly_order: int = 1
    gf_window: int = 5
    mw_k_sigma: float = 4.0
    mw_window: int = 100
    code_sigma_m: float = 0.3
    mw_prior_weight: float = 10.0
    mw_confirm: bool = True
    doppler_base_cycles: float = 0.5
    doppler_rate_cycles_per_s: float = 0.25
    max_gap_s: float | None = None
    lli_mask: int = 1


@dataclass(frozen=True)
class DetectorResult:
    """flags (N,) bool; statistic (N,) the tested quantity (NaN where not tested);
    threshold (N,) the limit |statistic| was compared with; outliers (N,) bool epochs
    rejected as outliers rather than slips (MW look-ahead only)."""

    flags: np.ndarray
    statistic: np.ndarray
    threshold: np.ndarray
    outliers: np.ndarray | None = None


@dataclass(frozen=True)
class SlipReport:
    """slip (N,): any detector fired; per-detector results/flags."""

    slip: np.ndarray
    lli: np.ndarray
    gap: np.ndarray
    gf: DetectorResult
    mw: DetectorResult
    doppler: DetectorResult
    max_gap_s: float = field(default=np.nan)


# --------------------------------------------------------------------------- combinations


def geometry_free(L1, L2):
    """GF = lambda1 L1 - lambda2 L2 [m]."""
    return LAMBDA_L1 * np.asarray(L1, float) - LAMBDA_L2 * np.asarray(L2, float)


def melbourne_wubbena(L1, L2, P1, P2):
    """MW = (L1 - L2) - (f1 P1 + f2 P2) / ((f1 + f2) lambda_WL) [wide-lane cycles]."""
    narrow_lane_code = (F_L1 * np.asarray(P1, float) + F_L2 * np.asarray(P2, float)) / (F_L1 + F_L2)
    return np.asarray(L1, float) - np.asarray(L2, float) - narrow_lane_code / LAMBDA_WL


def mw_prior_sigma_cycles(code_sigma_m: float) -> float:
    """sigma of MW from white code noise of sigma code_sigma_m on P1 and P2 [WL cycles]."""
    return code_sigma_m * np.hypot(F_L1, F_L2) / (F_L1 + F_L2) / LAMBDA_WL


# --------------------------------------------------------------------------- kernels


@njit(cache=True)
def _gf_kernel(t, gf, threshold, order, window, reset):
    n = t.size
    flags = np.zeros(n, dtype=np.bool_)
    stat = np.full(n, np.nan)
    hist = np.empty(window, dtype=np.int64)
    n_hist = 0
    for k in range(n):
        if not np.isfinite(gf[k]):
            continue
        if reset[k]:
            n_hist = 0
        if n_hist > 0:
            p = min(order, n_hist - 1)
            first = 0 if p > 0 else n_hist - 1  # order 0: last value (epoch difference)
            tau0 = t[k] - t[hist[first]]
            span = tau0 if tau0 > 0 else 1.0
            A = np.zeros((p + 1, p + 1))
            b = np.zeros(p + 1)
            for h in range(first, n_hist):
                x = (t[hist[h]] - t[k]) / span
                pw = np.ones(p + 1)
                for i in range(1, p + 1):
                    pw[i] = pw[i - 1] * x
                for i in range(p + 1):
                    b[i] += pw[i] * gf[hist[h]]
                    for j in range(p + 1):
                        A[i, j] += pw[i] * pw[j]
            coef = np.linalg.solve(A, b)
            stat[k] = gf[k] - coef[0]  # prediction at x = 0 (epoch k)
            if abs(stat[k]) > threshold:
                flags[k] = True
                n_hist = 0
        if n_hist == window:
            for h in range(window - 1):
                hist[h] = hist[h + 1]
            n_hist -= 1
        hist[n_hist] = k
        n_hist += 1
    return flags, stat


@njit(cache=True)
def _window_stats(mw, hist, n_hist, sigma_prior, prior_weight):
    mean = 0.0
    for h in range(n_hist):
        mean += mw[hist[h]]
    mean /= n_hist
    ss = 0.0
    for h in range(n_hist):
        ss += (mw[hist[h]] - mean) ** 2
    var = (ss + prior_weight * sigma_prior**2) / (n_hist - 1 + prior_weight)
    return mean, np.sqrt(var * (1.0 + 1.0 / n_hist))


@njit(cache=True)
def _mw_kernel(mw, k_sigma, window, sigma_prior, prior_weight, confirm, reset):
    n = mw.size
    flags = np.zeros(n, dtype=np.bool_)
    outliers = np.zeros(n, dtype=np.bool_)
    stat = np.full(n, np.nan)
    thres = np.full(n, np.nan)
    hist = np.empty(window, dtype=np.int64)
    n_hist = 0
    for k in range(n):
        if not np.isfinite(mw[k]):
            continue
        if reset[k]:
            n_hist = 0
        if n_hist > 0:
            mean, sig = _window_stats(mw, hist, n_hist, sigma_prior, prior_weight)
            stat[k] = mw[k] - mean
            thres[k] = k_sigma * sig
            if abs(stat[k]) > thres[k]:
                is_slip = True
                if confirm:
                    k2 = k + 1
                    while k2 < n and not np.isfinite(mw[k2]):
                        k2 += 1
                    # a reset at k2 (e.g. LLI) does not spoil the check: MW(k2) back at the
                    # old mean means k was an outlier, whatever happens at k2
                    if k2 < n and abs(mw[k2] - mean) <= thres[k]:
                        is_slip = False
                if is_slip:
                    flags[k] = True
                    n_hist = 0
                else:
                    outliers[k] = True
                    continue
        if n_hist == window:
            for h in range(window - 1):
                hist[h] = hist[h + 1]
            n_hist -= 1
        hist[n_hist] = k
        n_hist += 1
    return flags, stat, thres, outliers


@njit(cache=True)
def _doppler_kernel(t, L1, D1, base, rate, max_gap):
    n = t.size
    flags = np.zeros(n, dtype=np.bool_)
    stat = np.full(n, np.nan)
    thres = np.full(n, np.nan)
    prev = -1
    for k in range(n):
        if not (np.isfinite(L1[k]) and np.isfinite(D1[k])):
            continue
        if prev >= 0:
            dt = t[k] - t[prev]
            if dt <= max_gap:
                stat[k] = (L1[k] - L1[prev]) + 0.5 * (D1[k] + D1[prev]) * dt
                thres[k] = base + rate * dt
                flags[k] = abs(stat[k]) > thres[k]
        prev = k
    return flags, stat, thres


# --------------------------------------------------------------------------- validation


def _as_series(x, n: int, name: str) -> np.ndarray:
    if x is None:
        return np.full(n, np.nan)
    arr = np.asarray(x, dtype=float)
    if arr.shape != (n,):
        raise SlipInputError(f"arc.{name} must have shape ({n},) like arc.time, got {arr.shape}")
    if np.any(np.isinf(arr)):
        raise SlipInputError(f"arc.{name} contains infinite values (use NaN for missing)")
    return arr


def _check_time(time) -> np.ndarray:
    t = np.asarray(time, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise SlipInputError(f"arc.time must be a non-empty 1-D array, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise SlipInputError("arc.time contains NaN or infinite values")
    if np.any(np.diff(t) <= 0):
        i = int(np.argmax(np.diff(t) <= 0))
        raise SlipInputError(f"arc.time is not strictly increasing (t[{i + 1}] = {t[i + 1]} "
                             f"after t[{i}] = {t[i]})")
    return t


def _reset_array(reset, n):
    if reset is None:
        return np.zeros(n, dtype=np.bool_)
    r = np.asarray(reset, dtype=np.bool_)
    if r.shape != (n,):
        raise SlipInputError(f"reset must have shape ({n},), got {r.shape}")
    return r


def _positive(value, name):
    if not (np.isfinite(value) and value > 0):
        raise SlipInputError(f"config.{name} must be a positive number, got {value}")


# --------------------------------------------------------------------------- detectors


def geometry_free_detector(time, L1, L2, threshold_m=0.05, poly_order=1, window=5,
                           reset=None) -> DetectorResult:
    """GF test: statistic = GF(k) - GF_pred(k) [m], GF_pred from a polynomial of order
    p = min(poly_order, n_prev - 1) fitted to the last <= window valid epochs since the last
    reset (external ``reset`` or own detection); p = 0 uses the previous epoch only (RTKLIB's
    epoch difference).  Flag when |statistic| > threshold_m."""
    t = _check_time(time)
    gf = geometry_free(_as_series(L1, t.size, "L1"), _as_series(L2, t.size, "L2"))
    _positive(threshold_m, "gf_threshold_m")
    if int(poly_order) < 0 or int(window) < 1:
        raise SlipInputError(f"config.gf_poly_order must be >= 0 and gf_window >= 1, got "
                             f"{poly_order} and {window}")
    flags, stat = _gf_kernel(t, gf, float(threshold_m), int(poly_order), int(window),
                             _reset_array(reset, t.size))
    return DetectorResult(flags, stat, np.where(np.isfinite(stat), threshold_m, np.nan))


def melbourne_wubbena_detector(L1, L2, P1, P2, k_sigma=4.0, window=100, code_sigma_m=0.3,
                               prior_weight=10.0, confirm=True, reset=None) -> DetectorResult:
    """MW k-sigma test: statistic = MW(k) - running mean [WL cycles], threshold
    k sigma_hat sqrt(1 + 1/n) with sigma_hat^2 = (sum of squared deviations + w s0^2) /
    (n - 1 + w), n = samples in the window (<= window) since the last reset, s0 the prior
    sigma from code_sigma_m, w = prior_weight.  With confirm, a candidate whose next valid
    epoch returns within the threshold is an outlier, not a slip (TurboEdit)."""
    L1 = np.asarray(L1, dtype=float)
    n = L1.size
    mw = melbourne_wubbena(L1, _as_series(L2, n, "L2"), _as_series(P1, n, "P1"),
                           _as_series(P2, n, "P2"))
    _positive(k_sigma, "mw_k_sigma")
    _positive(code_sigma_m, "code_sigma_m")
    if int(window) < 1 or not prior_weight >= 0:
        raise SlipInputError(f"config.mw_window must be >= 1 and mw_prior_weight >= 0, got "
                             f"{window} and {prior_weight}")
    flags, stat, thres, outl = _mw_kernel(mw, float(k_sigma), int(window),
                                          mw_prior_sigma_cycles(code_sigma_m),
                                          float(prior_weight), bool(confirm),
                                          _reset_array(reset, n))
    return DetectorResult(flags, stat, thres, outl)


def doppler_phase_detector(time, L1, D1, base_cycles=0.5, rate_cycles_per_s=0.25,
                           max_gap_s=np.inf) -> DetectorResult:
    """Doppler test: statistic = L1(k) - L1(p) + (D1(k) + D1(p))/2 (t_k - t_p) [cycles]
    (p = previous epoch with L1 and D1; RINEX: dL1/dt = -D1), threshold
    base + rate (t_k - t_p).  Intervals longer than max_gap_s are not tested."""
    t = _check_time(time)
    _positive(base_cycles, "doppler_base_cycles")
    if not rate_cycles_per_s >= 0:
        raise SlipInputError(f"config.doppler_rate_cycles_per_s must be >= 0, got "
                             f"{rate_cycles_per_s}")
    flags, stat, thres = _doppler_kernel(t, _as_series(L1, t.size, "L1"),
                                         _as_series(D1, t.size, "D1"), float(base_cycles),
                                         float(rate_cycles_per_s), float(max_gap_s))
    return DetectorResult(flags, stat, thres)


def loss_of_lock_detector(lli1=None, lli2=None, n=None, mask=1) -> np.ndarray:
    """True where (LLI1 | LLI2) & mask != 0 (RINEX LLI bit 0 = loss of lock)."""
    out = None
    for name, lli in (("lli1", lli1), ("lli2", lli2)):
        if lli is None:
            continue
        arr = np.asarray(lli, dtype=float)
        if n is not None and arr.shape != (n,):
            raise SlipInputError(f"arc.{name} must have shape ({n},), got {arr.shape}")
        bits = np.where(np.isfinite(arr), arr, 0).astype(np.int64)
        hit = (bits & int(mask)) != 0
        out = hit if out is None else out | hit
    if out is None:
        if n is None:
            raise SlipInputError("loss_of_lock_detector needs lli1, lli2 or n")
        out = np.zeros(n, dtype=bool)
    return out


def data_gap_detector(time, valid, max_gap_s) -> np.ndarray:
    """True at a valid epoch whose previous valid epoch is more than max_gap_s earlier."""
    t = _check_time(time)
    valid = np.asarray(valid, dtype=bool)
    flags = np.zeros(t.size, dtype=bool)
    idx = np.flatnonzero(valid)
    if idx.size > 1:
        flags[idx[1:]] = np.diff(t[idx]) > max_gap_s
    return flags


def detect_cycle_slips(arc: SatelliteArc, config: SlipConfig | None = None) -> SlipReport:
    """Run all detectors on one arc and OR them.  Resets chain so that a slip found by one
    detector restarts the history of the others: LLI | gap -> GF and MW; Doppler -> GF, MW;
    GF -> MW (the MW running mean must not straddle a slip it cannot see, e.g. (1, 1)).
    A detector does not test an epoch at which it is reset (flag False, statistic NaN there);
    ``slip`` is True there anyway.  max_gap_s (None) = 2 x median epoch interval."""
    cfg = config or SlipConfig()
    t = _check_time(arc.time)
    n = t.size
    L1 = _as_series(arc.L1, n, "L1")
    L2 = _as_series(arc.L2, n, "L2")
    P1 = _as_series(arc.P1, n, "P1")
    P2 = _as_series(arc.P2, n, "P2")
    D1 = _as_series(arc.D1, n, "D1")
    if cfg.max_gap_s is None:
        max_gap = 2.0 * float(np.median(np.diff(t))) if n > 1 else np.inf
    else:
        _positive(cfg.max_gap_s, "max_gap_s")
        max_gap = float(cfg.max_gap_s)
    lli = loss_of_lock_detector(arc.lli1, arc.lli2, n=n, mask=cfg.lli_mask)
    valid1, valid2 = np.isfinite(L1), np.isfinite(L2)
    gap = data_gap_detector(t, valid1, max_gap) | data_gap_detector(t, valid2, max_gap)
    base = (lli | gap) & (valid1 | valid2)
    dop = doppler_phase_detector(t, L1, D1, cfg.doppler_base_cycles,
                                 cfg.doppler_rate_cycles_per_s, max_gap)
    gf = geometry_free_detector(t, L1, L2, cfg.gf_threshold_m, cfg.gf_poly_order,
                                cfg.gf_window, reset=base | dop.flags)
    mw = melbourne_wubbena_detector(L1, L2, P1, P2, cfg.mw_k_sigma, cfg.mw_window,
                                    cfg.code_sigma_m, cfg.mw_prior_weight, cfg.mw_confirm,
                                    reset=base | dop.flags | gf.flags)
    slip = base | dop.flags | gf.flags | mw.flags
    return SlipReport(slip=slip, lli=lli, gap=gap, gf=gf, mw=mw, doppler=dop, max_gap_s=max_gap)
