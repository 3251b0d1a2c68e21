"""The forward/backward agreement statistic of a smoothed run (gmis.smoothed_run): RMS z ≈ 1
for independent errors of the stated size, ≫ 1 when one filter is off."""

from types import SimpleNamespace

import numpy as np
import pytest

from gmis.smoothed_run import forward_backward_agreement


def _run(offset_m=0.0, seed=0, k=4000, n=21):
    rng = np.random.default_rng(seed)
    sd_f, sd_b = 0.02, 0.05
    truth = rng.normal(size=(k, n))
    xf = truth + rng.normal(size=(k, n)) * sd_f
    xb = truth + rng.normal(size=(k, n)) * sd_b + offset_m
    forward = SimpleNamespace(x=xf, sd=np.full((k, n), sd_f))
    states = SimpleNamespace(idx=np.arange(k), x_backward=xb, sd_backward=np.full((k, n), sd_b))
    return SimpleNamespace(forward=forward, states=states)


def test_consistent_filters_give_rms_one():
    assert forward_backward_agreement(_run()) == pytest.approx(1.0, abs=0.03)


def test_a_diverged_backward_filter_shows():
    assert forward_backward_agreement(_run(offset_m=0.5)) > 9.0
