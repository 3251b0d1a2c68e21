"""AWV vs AGMWM on replicates with varying parameters (004 Theorems 1-2, Proposition 1),
SR/DR-AWV with a contaminated replicate."""

import numpy as np
import pytest

from calibration import processes as P
from calibration.multisignal import average_wv, ms_gmwm, multi_signal
from calibration.robust import robust_wavelet_variance
from calibration.wavelet_variance import wavelet_variance

MODEL = ("WN", "AR1")


def _draw(rng):  # 004 §IV Simulation I
    b = rng.beta
    return [4e-5 + b(8, 5) * 3e-5, 0.999 + b(7, 2) * 0.0009, 6e-10 + b(3, 5) * 2e-10]


def test_awv_targets_theta0_and_agmwm_the_mean_parameter():
    """With φ spread over 0.999..0.9999, ν is strongly non-linear in φ: the AWV's ν(θ̂) fits
    the mean WV, the AGMWM's does not (its θ̂ is the mean of the θ̂_i, Theorem 1)."""
    rng = np.random.default_rng(41)
    thetas = [_draw(rng) for _ in range(6)]
    wvs = [wavelet_variance(P.simulate(MODEL, t, 10 ** 6, rng), levels=13) for t in thetas]
    ms = multi_signal(wvs, MODEL)
    assert np.allclose(ms.agmwm_theta, np.mean([f.theta for f in ms.replicate_fits], axis=0))
    bar = average_wv(wvs)
    loss = lambda th: float(np.sum((bar.nu2 - P.model_wv(MODEL, th, bar.tau)) ** 2
                                   * bar.omega))
    assert loss(ms.awv.theta) < 0.5 * loss(ms.agmwm_theta)
    # MS-GMWM = AWV (004 Proposition 1)
    ms_theta = ms_gmwm(wvs, MODEL, start=ms.agmwm_theta)
    assert np.allclose(ms_theta, ms.awv.theta, rtol=1e-3)
    assert np.all(ms.spread > 0)


def test_dr_awv_resists_one_abnormal_replicate():
    rng = np.random.default_rng(42)
    theta = [5e-5, 0.9995, 7e-10]
    signals = [P.simulate(MODEL, theta, 2 ** 18, rng) for _ in range(5)]
    signals.append(P.simulate(MODEL, [5e-4, 0.9995, 7e-9], 2 ** 18, rng))  # 10× noisier
    wvs = [robust_wavelet_variance(s, levels=14) for s in signals]
    plain = multi_signal(wvs, MODEL, fit_replicates=False)
    trimmed = multi_signal(wvs, MODEL, trim=0.2, fit_replicates=False)
    assert plain.method == "SR-AWV" and trimmed.method == "DR-AWV"
    assert trimmed.awv.theta[0] == pytest.approx(theta[0], rel=0.1)
    assert plain.awv.theta[0] > 1.5 * theta[0]
