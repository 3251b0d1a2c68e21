"""The IMU σ floor from the static window (gmis.imu_noise_floor, issue 14): raised only when
the measured spread is significantly above the recipe σ, and said so."""

import math

import numpy as np

from gmis.imu_noise_floor import imu_noise_floor

SIGMA = np.r_[np.full(3, math.radians(0.75)), np.full(3, 0.16)]


def test_a_matching_imu_is_left_alone_over_seeds():
    changed = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        x = rng.normal(size=(500, 6)) * SIGMA
        out, note = imu_noise_floor(SIGMA, x[:, :3].std(0), x[:, 3:].std(0), 500, 5.0)
        changed += note is not None
        assert np.all(out >= SIGMA)
    assert changed <= 3          # 6 axes × level 0.001 × 200 seeds ≈ 1.2 expected


def test_vibration_above_the_recipe_sigma_raises_that_axis_and_says_so():
    gyro_std = np.radians([2.38, 0.41, 0.13])      # the real drive's idle spread
    accel_std = np.array([0.09, 0.07, 0.14])
    out, note = imu_noise_floor(SIGMA, gyro_std, accel_std, 3300, 33.0)
    assert out[0] == gyro_std[0] and np.array_equal(out[1:], SIGMA[1:])
    assert "gyro_x 0.75 -> 2.38 deg/s" in note and "imu_noise_from_static" in note
    assert "gyro_y" not in note


def test_too_few_samples_give_no_floor():
    out, note = imu_noise_floor(SIGMA, np.radians([5.0] * 3), [1.0] * 3, 150, 1.5)
    assert note is None and np.array_equal(out, SIGMA)
