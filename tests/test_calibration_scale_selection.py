"""Automatic smallest-scale choice (calibration.scale_selection): a record the model
describes keeps every scale; one whose first scales are shaped by a sensor-like filter
(3-sample moving average, which no WN/AR1/RW sum reproduces) loses exactly those."""

import numpy as np
from scipy.signal import lfilter

from calibration import processes as P
from calibration.scale_selection import choose_smallest_scale
from calibration.wavelet_variance import wavelet_variance

MODEL, THETA = ("WN", "AR1", "RW"), [1e-4, 0.999, 1e-8, 1e-11]


def test_clean_record_keeps_every_scale():
    x = P.simulate(MODEL, THETA, 2 ** 17, np.random.default_rng(31))
    dropped, tests, fit = choose_smallest_scale(wavelet_variance(x), MODEL)
    assert dropped == 0 and len(tests) == 1 and not tests[0].dropped
    assert fit.wv.tau[0] == 2.0


def test_filtered_record_drops_the_filtered_scales():
    x = P.simulate(MODEL, THETA, 2 ** 17, np.random.default_rng(32))
    y = lfilter(np.ones(3) / 3.0, [1.0], x)
    wv = wavelet_variance(y)
    dropped, tests, fit = choose_smallest_scale(wv, MODEL)
    assert 1 <= dropped <= 3, tests
    assert tests[0].dropped and tests[0].f_statistic > tests[0].critical
    assert not tests[-1].dropped
    assert fit.objective < 0.25 * tests[0].objective_with  # measured: 1833 → 280
