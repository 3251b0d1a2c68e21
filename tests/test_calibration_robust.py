"""Robust WV / RGMWM: unbiased without outliers, stable with them where the GMWM breaks."""

import numpy as np
import pytest

from calibration import processes as P
from calibration.gmwm import fit_gmwm
from calibration.robust import robust_wavelet_variance
from calibration.wavelet_variance import wavelet_variance

MODEL, THETA = ("WN", "AR1", "RW"), [3e-6, 0.9985, 1.2e-10, 7e-13]


def test_robust_wv_is_consistent_on_clean_gaussian_data():
    x = P.simulate(("WN",), [2.0], 2 ** 18, np.random.default_rng(1))
    wv = robust_wavelet_variance(x)
    assert np.allclose(wv.nu2[:8], 2.0 / wv.tau[:8], rtol=0.03)


def test_rgmwm_keeps_estimates_where_gmwm_breaks_with_3_percent_outliers():
    rng = np.random.default_rng(31)
    x = P.simulate(MODEL, THETA, 10 ** 6, rng)
    y = P.add_outliers(x, P.Outliers(0.03, 10.0), rng)
    classical = fit_gmwm(wavelet_variance(y), MODEL)
    robust = fit_gmwm(robust_wavelet_variance(y), MODEL)
    wn_c, wn_r = classical.theta[0] / THETA[0], robust.theta[0] / THETA[0]
    assert abs(wn_c - 1) > 1.0  # the classical WN variance is blown up (~×4)
    assert wn_r == pytest.approx(1.0, rel=0.05)
    assert robust.theta[1] == pytest.approx(THETA[1], abs=5e-4)
