"""Identified model → GMIKF noise inputs: rate scaling, RW/GM drift, the [noise] fragment."""

import tomllib

import numpy as np
import pytest

from calibration import filter_inputs as F
from calibration import processes as P
from calibration.gmwm import fit_gmwm
from calibration.wavelet_variance import wavelet_variance


def _fit(model, theta, dt=0.01, seed=0):
    x = P.simulate(model, theta, 2 ** 18, np.random.default_rng(seed))
    return fit_gmwm(wavelet_variance(x, dt), model)


def test_white_sigma_scales_with_the_imu_rate_and_rw_drift_per_step():
    fit = _fit(("WN", "RW"), [1e-4, 1e-10])
    at_100 = F.filter_noise(fit, 0.01)
    at_200 = F.filter_noise(fit, 0.005)
    wn, rw = fit.theta
    assert at_100["measurement_sigma"] == pytest.approx(np.sqrt(wn))
    assert at_200["measurement_sigma"] == pytest.approx(np.sqrt(2 * wn))  # N fixed, δt halved
    assert at_200["bias_drift_sigma_per_step"] == pytest.approx(np.sqrt(rw / 2))
    assert at_100["bias_drift_source"] == "RW"


def test_gauss_markov_parameters_and_rw_overbound_without_rw():
    fit = _fit(("WN", "AR1"), [1e-4, 0.999, 1e-8])
    noise = F.filter_noise(fit, 0.01)
    phi, s2 = fit.theta[1], fit.theta[2]
    gm = noise["gauss_markov"][0]
    assert gm["tau_s"] == pytest.approx(-0.01 / np.log(phi))
    assert gm["stationary_sigma"] == pytest.approx(np.sqrt(s2 / (1 - phi ** 2)))
    assert gm["phi_at_imu_rate"] == pytest.approx(phi)
    assert noise["bias_drift_source"].startswith("AR1 over-bound")
    # the over-bounding RW matches the AR1's WV at τ = 4 (000 eq. 4.8)
    g2 = F.rw_overbound_of_ar1(phi, s2)
    assert P.rw_wv(g2, 4.0) == pytest.approx(P.ar1_wv(phi, s2, np.array([4.0]))[0])


def test_fragment_is_a_noise_table_in_recipe_units():
    fit = _fit(("WN", "RW"), [(0.3 * np.pi / 180) ** 2, 1e-12])
    noise = {f"{k}_{a}": F.filter_noise(fit, 0.01) for k in ("gyro", "accel") for a in "xyz"}
    doc = tomllib.loads(F.noise_fragment(noise, "test"))
    assert set(doc) == {"noise"}
    assert set(doc["noise"]) == {"gyro_deg_s", "gyro_bias_drift_deg_s", "accel_m_s2",
                                 "accel_bias_drift_m_s2"}
    assert doc["noise"]["gyro_deg_s"][0] == pytest.approx(0.3, rel=0.02)
