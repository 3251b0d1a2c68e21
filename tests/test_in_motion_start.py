"""Issue 20 item 1: a drive moving at its first sample (simulated: 15 m/s, accelerating,
then turning) is initialised from the GNSS kinematics and the gravity-compensated
specific force, not levelled as if at rest."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gmis.motion_initialisation import fit_constant_jerk, level_in_motion

SCENARIO = """
[scenario]
name = "moving-start"
seed = 2020
start_gps_s = 345600.0
imu_rate_hz = 100.0

[origin]
lat_deg = 40.0
lon_deg = -105.2
h_m = 1600.0

[initial]
heading_deg = 30.0
speed_m_s = 15.0
pitch_deg = -4.0

[[segment]]
type = "accelerate"
speed_m_s = 25.0
accel_m_s2 = 2.0
ramp_s = 0.2

[[segment]]
type = "turn"
angle_deg = 60.0
rate_deg_s = 10.0

[[segment]]
type = "cruise"
duration_s = 30.0

[imu]
grade = "IMU440"
gyro_bias_deg_h = [180.0, -120.0, 90.0]
accel_bias_mg = [5.0, -3.0, 8.0]

[gnss]
rate_hz = 5.0
position_sigma_m = [0.02, 0.02, 0.04]
velocity_sigma_m_s = [0.05, 0.05, 0.05]
lever_arm_m = [0.3, 1.0, 1.5]

[heading]
rate_hz = 5.0
sigma_deg = 0.5
lever_arm_m = [0.3, -1.0, 1.5]
"""


def test_constant_jerk_fit_is_exact_on_a_cubic():
    t = 100.0 + np.arange(0.0, 2.01, 0.2)
    tau = t - 100.0
    r0, v0, a = np.array([1.0, -2.0, 3.0]), np.array([10.0, 5.0, -0.5]), \
        np.array([0.7, -1.2, 0.1])
    j = np.array([0.3, 0.0, -0.2])
    pos = r0 + np.outer(tau, v0) + np.outer(tau ** 2, a) / 2 + np.outer(tau ** 3, j) / 6
    vel = v0 + np.outer(tau, a) + np.outer(tau ** 2, j) / 2
    fit = fit_constant_jerk(t, pos, np.full_like(pos, 0.02), 100.0, 2.0, vel,
                            np.full_like(pos, 0.05))
    assert fit.r0 == pytest.approx(r0, abs=1e-8)
    assert fit.v0 == pytest.approx(v0, abs=1e-8)
    assert fit.a == pytest.approx(a, abs=1e-8)
    assert fit.a_mean == pytest.approx(a + j, abs=1e-8)  # mean over 2 s: a + j·1 s
    assert fit.chi2_scale == 1.0 and fit.n_epochs == 11
    assert fit_constant_jerk(t[:4], pos[:4], np.full((4, 3), 0.02), 100.0) is None


def test_levelling_with_the_acceleration_removed_recovers_the_attitude():
    from gmis.frames import dcm_body_to_nav
    pitch, roll, heading = np.radians([-4.3, 2.0, 30.0])
    g = np.array([0.0, 0.0, -9.80])
    acc = np.array([1.0, 1.7, -0.1])  # accelerating and climbing
    f = dcm_body_to_nav(pitch, roll, heading).T @ (acc - g)
    p, r = level_in_motion(f, acc, g, heading)
    assert (p, r) == pytest.approx((pitch, roll), abs=1e-9)
    # the static levelling (acceleration ignored) is degrees off: the test can fail
    p_static, _ = level_in_motion(f, np.zeros(3), g, heading)
    assert abs(np.degrees(p_static - pitch)) > 5.0


@pytest.fixture(scope="module")
def moving_run(tmp_path_factory):
    from gmis.navigation_solution import navigation_solution, reference_errors
    from gmis.recipe import load_recipe
    from gmis.run_preparation import prepare_run, run_prepared
    from gmis.simulate import simulate_scenario

    root = tmp_path_factory.mktemp("moving")
    (root / "moving.toml").write_text(SCENARIO)
    sim = simulate_scenario(root / "moving.toml", root / "dataset")
    path = Path(sim.recipe_path)
    # no heading stream: the heading must come from the GNSS course
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("heading =")]
    path.write_text("\n".join(lines) + "\n")
    recipe = load_recipe(path)
    assert recipe.paths.heading is None
    prep = prepare_run(recipe)
    rec = run_prepared(prep)
    return prep, reference_errors(prep, rec, navigation_solution(prep, rec))


def test_moving_start_initial_state_is_close_to_truth_within_its_sigma(moving_run):
    from gmis.state import ATT, VEL
    prep, _ = moving_run
    ref = prep.dataset.reference
    truth = ref.euler[0]  # pitch, roll, heading at t0
    err = np.degrees(prep.x0[ATT] - truth)
    err[2] = (err[2] + 180.0) % 360.0 - 180.0
    sd = np.degrees(prep.config.p0_sd[ATT])
    assert np.all(np.abs(err) < 3.0 * sd), (err, sd)
    # a static levelling would read the 1.8 m/s² acceleration as ~10° of pitch
    assert abs(err[0]) < 1.0 and abs(err[1]) < 1.0 and abs(err[2]) < 1.0, err
    speed = np.linalg.norm(prep.x0[VEL])
    assert speed == pytest.approx(np.linalg.norm(ref.vel_enu[0]), abs=0.3)
    assert any("start in motion" in w for w in prep.dataset.warnings)


def test_moving_start_run_is_consistent_after_10_s(moving_run):
    _, errs = moving_run
    late = errs["t"] >= errs["t"][0] + 10.0
    assert np.degrees(np.abs(errs["att"][late, 2])).max() < 1.0
    assert np.sqrt(np.mean(errs["pos"][late] ** 2, axis=0)).max() < 0.05
    for name in ("position", "velocity_body", "attitude"):
        assert np.mean(errs["nees"][name][late]) < 3.0 * 1.5, name  # 3 dof, mean NEES


def test_moving_start_floors_the_imu_sigma_from_second_differences(moving_run):
    """No static window: the IMU σ floor comes from the Δ² noise of the first 20 s
    (gmis.imu_noise_floor.imu_noise_in_motion) — the simulated IMU matches its recipe σ and
    is left alone; a recipe claiming a third of the gyro noise is raised back to it."""
    from dataclasses import replace

    from gmis.run_preparation import prepare_run

    prep, _ = moving_run
    assert not any("IMU noise in motion" in w for w in prep.dataset.warnings)
    recipe = prep.recipe
    true_gyro = np.asarray(recipe.noise.gyro_sigma_rad_s, float)
    assert np.allclose(prep.config.imu_sd[:3], true_gyro, rtol=1e-3)   # no floor
    low = replace(recipe, noise=replace(recipe.noise,
                                        gyro_sigma_rad_s=tuple(true_gyro / 3.0)))
    raised = prepare_run(low)
    assert np.allclose(raised.config.imu_sd[:3], true_gyro, rtol=0.1), (
        raised.config.imu_sd[:3], true_gyro)
    assert np.allclose(raised.config.imu_sd[3:], prep.config.imu_sd[3:])
    assert any("IMU noise in motion (second differences over the first 20.0 s" in w
               for w in raised.dataset.warnings)


def test_moving_start_with_the_imu_on_disk_equals_in_memory(moving_run):
    """The streamed run's preparation (IMU samples on disk, gmis.imu_spool: the moving
    start, the course heading and the in-motion noise floor read them whole) and its
    chunked filter give the in-memory preparation's x0, σ and records."""
    from dataclasses import replace

    from gmis.imu_spool import ImuSpool
    from gmis.readers import load_dataset
    from gmis.run_preparation import prepare_run, run_prepared, streams_imu

    prep, _ = moving_run
    recipe = prep.recipe
    assert streams_imu(recipe)
    disk = prepare_run(recipe, load_dataset(recipe, imu_on_disk=True))
    assert isinstance(disk.meas.imu_z, ImuSpool) and disk.in_motion is not None
    np.testing.assert_array_equal(disk.x0, prep.x0)
    np.testing.assert_array_equal(disk.config.p0_sd, prep.config.p0_sd)
    np.testing.assert_array_equal(disk.config.imu_sd, prep.config.imu_sd)
    xs = {}
    for name, p in (("memory", prep), ("disk", disk)):
        p = replace(p, config=replace(p.config, chunk=501))
        parts = []
        run_prepared(p, sink=lambda e0, rec, parts=parts: parts.append(rec.x.copy()))
        xs[name] = np.concatenate(parts)
    np.testing.assert_array_equal(xs["disk"], xs["memory"])
