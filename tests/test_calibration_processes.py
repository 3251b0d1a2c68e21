"""Theoretical Haar WV of each process against a direct computation and simulation."""

import numpy as np
import pytest

from calibration import processes as P
from calibration.wavelet_variance import wavelet_variance


def _haar_var_from_acov(acov, tau):
    """var of the MODWT Haar coefficient from an autocovariance function (brute force)."""
    m = tau // 2
    c = np.r_[np.ones(m), -np.ones(m)] / tau
    i = np.arange(tau)
    return c @ acov(np.abs(i[:, None] - i[None, :])) @ c


@pytest.mark.parametrize("phi", [0.3, 0.9, 0.995])
def test_ar1_wv_matches_autocovariance(phi):
    xi2 = 2.5
    s2 = xi2 / (1 - phi ** 2)
    for tau in (2, 4, 8, 32, 128):
        exact = _haar_var_from_acov(lambda h: s2 * phi ** h, tau)
        assert P.ar1_wv(phi, xi2, np.array([float(tau)]))[0] == pytest.approx(exact, rel=1e-10)


def test_ar1_wv_stable_near_one_where_closed_form_fails():
    tau = 2.0 ** np.arange(1, 8)
    phi = 1 - 1e-8  # AR1 ≈ RW of the same innovation variance at small scales
    stable = P.ar1_wv(phi, 1.0, tau)
    assert np.allclose(stable, P.rw_wv(1.0, tau), rtol=1e-5)
    closed = P.ar1_wv_closed_form(phi, 1.0, tau)
    assert np.max(np.abs(closed / stable - 1)) > 1e-2  # 000 Table 3.2 as printed loses it


def test_rw_qn_wn_dr_wv_match_autocovariance_or_definition():
    for tau in (2, 4, 16):
        assert P.wn_wv(3.0, tau) == pytest.approx(_haar_var_from_acov(
            lambda h: 3.0 * (h == 0), tau))
        # QN: X_t = Q (U_t − U_{t−1}): acov 2Q² at 0, −Q² at 1
        assert P.qn_wv(2.0, tau) == pytest.approx(_haar_var_from_acov(
            lambda h: 2.0 * (2.0 * (h == 0) - 1.0 * (h == 1)), tau))
    # DR: a deterministic ramp's Haar coefficient is ω τ / 4
    x = 0.3 * np.arange(1, 2001)
    wv = wavelet_variance(x)
    assert np.allclose(wv.nu2, P.dr_wv(0.3, wv.tau), rtol=1e-9)


def test_simulated_composite_wv_inside_ci_at_nominal_rate():
    rng = np.random.default_rng(11)
    model, theta = ("WN", "QN", "AR1", "RW"), [1e-4, 2e-5, 0.995, 1e-8, 1e-12]
    inside, total = 0, 0
    for _ in range(4):
        wv = wavelet_variance(P.simulate(model, theta, 2 ** 18, rng))
        true = P.model_wv(model, theta, wv.tau)
        inside += np.sum((wv.ci_low <= true) & (true <= wv.ci_high))
        total += true.size
    assert inside / total > 0.85


def test_model_parsing():
    assert P.parse_model("WN+QN+2*AR1+RW+DR") == ("WN", "QN", "AR1", "AR1", "RW", "DR")
    assert P.model_name(("RW", "AR1", "WN", "AR1")) == "WN+2*AR1+RW"
    with pytest.raises(ValueError):
        P.parse_model("WN+WN")
    with pytest.raises(ValueError):
        P.parse_model("WN+XX")
