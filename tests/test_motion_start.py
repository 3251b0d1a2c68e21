"""Start of a run without a static-only window or a heading sensor: gmis.motion.first_motion
(alignment window cut) and gmis.course_heading.heading_from_course."""

from __future__ import annotations

import numpy as np
import pytest

from gmis.course_heading import heading_from_course
from gmis.motion import first_motion

RATE = 100.0


def _imu(n_still_s=20.0, n_total_s=40.0, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, n_total_s, 1 / RATE)
    gyro = rng.normal(0.0, 0.01, (t.size, 3))  # white rate noise, zero mean
    accel = rng.normal(0.0, 0.1, (t.size, 3)) + [0.3, 0.0, 9.8]
    moving = t >= n_still_s
    accel[moving, 1] += 1.0  # pulls away forward at 1 m/s²
    return t, gyro, accel


def test_first_motion_from_imu():
    t, gyro, accel = _imu()
    assert first_motion(t, gyro, accel, 0.0) == pytest.approx(20.0)


def test_first_motion_from_gnss_speed_comes_first():
    t, gyro, accel = _imu()
    gt = np.arange(0.0, 40.0, 0.25)
    speed = np.where(gt >= 15.0, 0.5, 0.01)
    assert first_motion(t, gyro, accel, 0.0, gt, speed) == pytest.approx(15.0)


def test_parked_receivers_velocity_noise_is_not_motion():
    """A parked receiver's 5 cm/s per-axis velocity noise: over 300 s at 5 Hz its Rayleigh
    speed passes 0.2 m/s at a few epochs in ~40 % of drives (each a false 'motion' that
    cut the alignment window); lone epochs are not motion, a sustained start is, dated at
    its first epoch."""
    t, gyro, accel = _imu(n_still_s=400.0, n_total_s=300.0)
    gt = np.arange(0.0, 300.0, 0.2)
    rng = np.random.default_rng(3)
    speed = np.hypot(*rng.normal(0.0, 0.05, (2, gt.size)))
    speed[[100, 700, 1200]] = 0.25                       # lone noise spikes
    assert first_motion(t, gyro, accel, 0.0, gt, speed) is None
    speed[1400:] = 0.5                                   # drives off at t = 280 s
    assert first_motion(t, gyro, accel, 0.0, gt, speed) == pytest.approx(280.0)


def test_no_motion_gives_none():
    t, gyro, accel = _imu(n_still_s=100.0)
    gt = np.arange(0.0, 40.0, 0.25)
    assert first_motion(t, gyro, accel, 0.0, gt, np.full(gt.size, 0.05)) is None


def test_heading_from_course_carries_back_the_turn():
    # parked at heading 30°, a 20° left turn (ω_z > 0 about up) over 10..15 s, then a
    # straight run at course 30° − 20° = 10°
    t = np.arange(0.0, 30.0, 1 / RATE)
    omega = np.radians(20.0) / 5.0
    gyro_z = np.where((t >= 10.0) & (t < 15.0), omega, 0.0) + 0.002  # + a 0.002 rad/s bias
    gt = np.arange(0.0, 30.0, 0.25)
    speed = np.where(gt >= 16.0, 5.0, 0.0)
    course = np.radians(10.0)
    vel = np.column_stack([speed * np.sin(course), speed * np.cos(course), 0 * gt])
    heading, sigma, t1 = heading_from_course(gt, vel, t, gyro_z, 0.002, 0.0)
    assert np.degrees(heading) == pytest.approx(30.0, abs=0.05)
    assert t1 == pytest.approx(16.375)
    assert np.degrees(sigma) == pytest.approx(5.0)
    assert heading_from_course(gt, vel * 0.1, t, gyro_z, 0.002, 0.0) is None


@pytest.mark.parametrize("still_s, window_s, expected_s, cut", [
    (20.0, 60.0, 19.0, True),    # motion inside the window: cut 1 s before it
    (20.0, 15.0, 15.0, False),   # motion after the window: kept, no warning
    (0.5, 60.0, 60.0, False),    # motion from the start: kept, with a warning
])
def test_static_window_cut(still_s, window_s, expected_s, cut):
    from gmis.readers import Dataset, ImuData
    from gmis.run_preparation import _static_window
    t, gyro, accel = _imu(n_still_s=still_s)
    if still_s < 1.0:
        accel[:, 1] += np.arange(t.size) * 0.01  # accelerating from the first sample
    ds = Dataset(recipe=None, imu=ImuData(t=t, gyro=gyro, accel=accel))
    win, warning = _static_window(ds, 0.0, window_s)
    assert win == pytest.approx(expected_s)
    if cut:
        assert "window cut to 19.0 s" in warning
    elif still_s < 1.0:
        assert "kept as given" in warning
    else:
        assert warning is None
