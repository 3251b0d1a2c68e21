"""Printed consistency warnings of a run (issue 14 item 4): rejections above expectation and
a mean normalised innovation away from 1, per measurement group."""

from types import SimpleNamespace

import numpy as np

from gmis.gmikf import N_SLOTS, SLOT_NAMES, SLOT_POS, SLOT_VEL
from gmis.run_statistics import consistency_warnings


def _records(scale_pos=1.0, rejected_pos=0, n=2000, seed=0):
    rng = np.random.default_rng(seed)
    innov = np.full((n, N_SLOTS), np.nan)
    var = np.full((n, N_SLOTS), np.nan)
    for i in range(SLOT_POS, SLOT_VEL + 3):
        var[:, i] = 0.01
        innov[:, i] = rng.normal(size=n) * 0.1 * (scale_pos if i < SLOT_VEL else 1.0)
    rejected = np.zeros((n, N_SLOTS), dtype=np.int8)
    rejected[:rejected_pos, SLOT_POS] = 1
    return SimpleNamespace(innov=innov, innov_var=var, rejected=rejected)


def test_a_consistent_run_warns_nothing():
    assert consistency_warnings(_records(), 0.001) == []


def test_too_small_sigmas_and_too_many_rejections_are_named():
    lines = consistency_warnings(_records(scale_pos=2.0, rejected_pos=200), 0.001)
    assert len(lines) == 2 and all(line.startswith("gnss_position:") for line in lines)
    assert "200 of 6000" in lines[0] and "sigmas too small" in lines[1]
    assert not any("gnss_velocity" in line for line in lines)
    assert SLOT_NAMES[SLOT_POS] == "pos_e"
