"""[gnss].velocity_time_offset_s: the GNSS velocity moved to its own epochs (a receiver
whose velocity lags its position), the position untouched."""

from dataclasses import replace

import numpy as np
import pytest

from gmis.errors import GmisInputError


def _rows_and_times(idx, t):
    have = idx >= 0
    return idx[have], t[have]


def test_velocity_rows_move_by_the_offset_and_positions_stay(tmp_path):
    from gmis.recipe import load_recipe
    from gmis.run_preparation import prepare_run
    from gmis.simulate import simulate_scenario
    from tests.test_batch import _short_scenario

    sim = simulate_scenario(_short_scenario(tmp_path / "s.toml"), tmp_path / "ds")
    recipe = load_recipe(sim.recipe_path)
    base = prepare_run(recipe)
    moved = prepare_run(replace(recipe, gnss=replace(recipe.gnss,
                                                     velocity_time_offset_s=-0.15)))
    pos0, tp0 = _rows_and_times(base.epochs.pos, base.epochs.t)
    pos1, tp1 = _rows_and_times(moved.epochs.pos, moved.epochs.t)
    assert np.array_equal(pos0, pos1) and np.array_equal(tp0, tp1)
    vel0, tv0 = _rows_and_times(base.epochs.vel, base.epochs.t)
    assert np.array_equal(tv0, tp0)                    # no offset: same epochs
    vel1, tv1 = _rows_and_times(moved.epochs.vel, moved.epochs.t)
    assert vel1.size >= vel0.size - 1
    t_row = dict(zip(vel0.tolist(), tv0.tolist()))
    common = [k for k, r in enumerate(vel1.tolist()) if r in t_row]
    assert len(common) >= vel0.size - 1
    shift = np.array([tv1[k] - t_row[int(vel1[k])] for k in common])
    np.testing.assert_allclose(shift, -0.15, atol=1e-9)
    np.testing.assert_array_equal(moved.meas.vel_enu, base.meas.vel_enu)
    assert not np.isin(tv1, tp1).any()                 # velocity on epochs of its own


def test_out_of_range_offset_is_refused(tmp_path):
    from tests.test_consumer_recipe_keys import _load

    with pytest.raises(GmisInputError, match=r"gnss.velocity_time_offset_s"):
        _load(tmp_path, "[gnss]\nvelocity_time_offset_s = 6.0\n")
    assert _load(tmp_path, "[gnss]\nvelocity_time_offset_s = -0.15\n").gnss \
        .velocity_time_offset_s == -0.15
