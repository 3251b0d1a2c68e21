"""Data-driven choice of the smallest wavelet scale the composite model is fitted on.

Why: the first scales of a real IMU record can be shaped by what no WN/QN/AR1/RW/DR sum
describes — the sensor's decimation/anti-alias filter (negative correlation at a few
samples), aliasing, quantisation steps. Their χ² CIs are the tightest, so when they are
fitted the misfit there drags every other scale (ADIS16405 gyro z, WN+QN+2AR1+RW on the
AWV: objective 27 096 on 18 scales, the implied WV outside the CI at 10). 000 §4.2
removes such scales; here it is a goodness-of-fit decision, not a number typed by the
user.

Test of the leading scale k (scales k, k+1, … fitted so far): refit on scales > k and
compare the fall of the GMWM objective with the misfit per residual degree of freedom of
the refit,

    F_k = (Q_{≥k} − Q_{>k}) / (Q_{>k} / (J_{>k} − p)),

J_{>k} the scales left, p the model's parameters. If the model describes scale k as well
as the others, leaving it out removes about one scale's share of the objective, F ≈ 1 (an
F(1, J−p) law when the misfit is noise; the same ≈ 1 when the model is misspecified
evenly over the scales — real records are, with 4 × 1e6 samples every model is rejected
somewhere, so an absolute χ² test would drop scales without end). A scale the model
cannot describe carries most of Q: F ≫ 1. Scale k is dropped while F_k exceeds the
F(1, J_{>k} − p) quantile at 1 − ``level`` (default 1e-3); the first k that passes is the
smallest scale used. At most ``max_drop`` scales go, and ≥ p + 3 scales stay. Each test
costs one fit; the table of tests goes into calibration.json.

The test model is the largest model with at most ``MAX_TEST_AR1`` (2) AR1 terms. A third
AR1 with a time constant of about one sample reproduces a decimation filter's shape at the
first scales, and then hides exactly what the test is for (ADIS16405 gyro z with
WN+QN+3AR1+RW: the 0.04 s scale gives F = 23.5 against the critical 29.2 and stays, the
fit's objective 2 878; with two AR1s F = 83.5, 30.5, 1 855 drop 0.02-0.08 s and the
objective is 2.8). The model itself is chosen afterwards, on the kept scales, among all
nested models of the largest one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.stats import f as f_dist

from calibration import processes as P
from calibration.wavelet_variance import WaveletVariance

LEVEL = 1e-3
MAX_DROP = 4
MAX_TEST_AR1 = 2


@dataclass(frozen=True)
class ScaleTest:
    scale: int  # index of the tested scale (0 = the smallest, τ = 2 samples)
    tau_s: float
    objective_with: float  # Q on scales ≥ this one
    objective_without: float  # Q refitted on the scales above it
    f_statistic: float
    critical: float  # F(1, J − p) quantile at 1 − level
    dropped: bool

    def as_dict(self) -> dict:
        return asdict(self)


def scale_test_model(model, max_ar1: int = MAX_TEST_AR1) -> tuple[str, ...]:
    """``model`` without its AR1 terms beyond the first ``max_ar1`` (module doc)."""
    kept, n_ar1 = [], 0
    for process in P.canonical(model):
        n_ar1 += process == "AR1"
        if process != "AR1" or n_ar1 <= max_ar1:
            kept.append(process)
    return tuple(kept)


def choose_smallest_scale(wv: WaveletVariance, model, level: float = LEVEL,
                          max_drop: int = MAX_DROP, fit=None):
    """(number of leading scales to drop, [ScaleTest], the GMWM fit (θ̂ and objective, no
    SEs) on the kept scales of the test model, scale_test_model(model)). ``fit``: that model's fit on all of wv's
    scales, if already done."""
    from calibration.gmwm import fit_gmwm

    model = scale_test_model(model)
    p = P.n_params(model)
    current = fit if fit is not None else fit_gmwm(wv, model, se="none")
    tests, k = [], 0
    while k < max_drop and wv.tau.size - (k + 1) >= p + 3:
        rest = fit_gmwm(wv.select(np.arange(k + 1, wv.tau.size)), model, se="none")
        dof = wv.tau.size - (k + 1) - p
        per_dof = max(rest.objective, 1e-300) / dof
        stat = (current.objective - rest.objective) / per_dof
        crit = float(f_dist.ppf(1.0 - level, 1, dof))
        drop = bool(stat > crit)
        tests.append(ScaleTest(k, float(wv.tau_s[k]), float(current.objective),
                               float(rest.objective), float(stat), crit, drop))
        if not drop:
            break
        k, current = k + 1, rest
    return k, tests, current
