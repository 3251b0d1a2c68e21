"""A vehicle turning on the spot is not at rest (helper review 2026-12-06): its antenna
moves slower than any GNSS speed threshold, so the stillness test alone froze the
dynamics through a 90° turn at 10°/s — gyro-z bias 40σ off, attitude NEES ~50. The IMU
vetoes stillness when the mean angular rate over the window exceeds 2°/s."""

from __future__ import annotations

import numpy as np

from gmis.epochs import merge_streams
from gmis.motion import STILL_MAX_RATE_RAD_S, stationary_epochs

SEGMENTS = [{"type": "static", "duration_s": 30.0},
            {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 10.0},    # on the spot
            {"type": "static", "duration_s": 10.0},
            {"type": "accelerate", "speed_m_s": 8.0, "accel_m_s2": 1.0},
            {"type": "cruise", "duration_s": 10.0}]


def turn_scenario(gnss_outages=()) -> str:
    from tests.simulated_drives import scenario_toml
    return scenario_toml("turn-on-the-spot", SEGMENTS, seed=7, gnss_outages=gnss_outages)


def test_the_imu_vetoes_stillness_while_turning():
    t = np.arange(0.0, 60.0, 0.01)
    gyro = np.zeros((t.size, 3)) + np.radians([0.3, -0.2, 0.5])   # MEMS biases: still
    turning = (t >= 20.0) & (t < 29.0)
    gyro[turning, 2] += np.radians(10.0)
    gnss_t = np.arange(0.0, 60.0, 0.2)
    slow = np.full(gnss_t.size, 0.05)                               # the antenna: slow
    epochs = merge_streams(t, gnss_t)
    plain = stationary_epochs(epochs, gnss_t, slow)
    vetoed = stationary_epochs(epochs, gnss_t, slow, imu=(t, gyro))
    assert plain[turning].all()                          # GNSS alone: "at rest"
    assert not vetoed[(t >= 19.5) & (t < 29.5)].any()     # the window reaches 1 s out
    assert vetoed[(t > 2.0) & (t < 18.0)].all() and vetoed[(t > 31.0) & (t < 58.0)].all()
    assert np.radians(0.5) < STILL_MAX_RATE_RAD_S < np.radians(10.0)


def test_a_turn_on_the_spot_keeps_the_filter_consistent(tmp_path):
    from gmis.pipeline import run_recipe
    from gmis.simulate import simulate_scenario

    (tmp_path / "scenario.toml").write_text(turn_scenario())
    sim = simulate_scenario(tmp_path / "scenario.toml", tmp_path / "ds")
    s = run_recipe(sim.recipe_path, tmp_path / "out")
    nees = s["errors_vs_reference"]["nees_mean"]
    # before the veto: position / velocity / attitude 4.4 / 10.2 / 50.8, heading RMS 1.3°
    assert nees["attitude"] < 4.5 and nees["velocity_body"] < 4.5, nees
    assert s["errors_vs_reference"]["attitude"]["heading"]["rms"] < 0.3

