"""Overlapping AV against allantools (the independent implementation) and noise
coefficient recovery from simulated processes."""

import numpy as np
import pytest

from calibration import processes as P
from calibration.allan import BI_FACTOR, allan_variance, line_fits, line_fits_of

allantools = pytest.importorskip("allantools")


def test_oadev_and_line_fits_agree_with_allantools():
    rng = np.random.default_rng(5)
    x = P.simulate(("QN", "WN", "RW"), [4e-4, 1e-4, 1e-12], 10 ** 6, rng)
    av = allan_variance(x, 0.01)
    taus, adev, _, _ = allantools.oadev(x, rate=100.0, data_type="freq", taus=av.tau_s)
    assert np.allclose(taus, av.tau_s)
    assert np.allclose(av.adev, adev, rtol=1e-9)
    ours, theirs = line_fits(av.tau_s, av.adev), line_fits(taus, adev)
    for name, fit in ours.items():
        if fit is None:
            assert theirs[name] is None
        else:
            assert theirs[name].coefficient == pytest.approx(fit.coefficient, rel=1e-6)
            assert theirs[name].tau_range_s == fit.tau_range_s


def test_arw_and_rrw_recovered_within_10_percent():
    rng = np.random.default_rng(6)
    dt, sigma2, gamma2 = 0.01, 1e-4, 1e-9
    fits = line_fits_of(allan_variance(P.simulate(("WN", "RW"), [sigma2, gamma2], 10 ** 6,
                                                  rng), dt))  # RW dominant from τ ≈ 10 s
    assert fits["random_walk"].coefficient == pytest.approx(np.sqrt(sigma2 * dt), rel=0.1)
    assert fits["random_walk"].tau_range_s[0] == pytest.approx(dt)
    assert fits["rate_random_walk"].coefficient == pytest.approx(np.sqrt(gamma2 / dt), rel=0.1)


def test_bias_instability_of_flicker_noise_recovered_within_10_percent():
    """Flicker noise with one-sided PSD h/f has the flat AV 2 ln2 h (Barnes et al. 1971),
    so B = √(AV)/√(2 ln2/π) = √(π h). This FFT-shaped simulation's AV is flat only up to
    τ ≈ 20 s (T/500); the reading is made on that range."""
    rng = np.random.default_rng(7)
    n, dt, f0 = 2 ** 20, 0.01, 1.0
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, dt)
    spec[1:] *= np.sqrt(f0 / f[1:])
    spec[0] = 0.0
    x = np.fft.irfft(spec, n)
    h = 2.0 * dt * f0  # one-sided PSD of unit white noise is 2Δt
    av = allan_variance(x, dt)
    fits = line_fits_of(av, tau_max_s=20.0)
    assert fits["bias_instability"].coefficient == pytest.approx(np.sqrt(np.pi * h), rel=0.1)
    assert BI_FACTOR == pytest.approx(0.664, abs=1e-3)
