"""gmis.mounting: roll/pitch/yaw mounting rotations, FRD → RFU, composition with [imu].axes;
checked on the real drive: the stationary specific force points up in body RFU and the
gyro's turn about body z matches the GNSS course rate (sign and magnitude)."""

from __future__ import annotations

import numpy as np
import pytest

from gmis.mounting import FRD_TO_RFU, mounting_matrix, rpy_dcm
from gmis.recipe import axes_matrix
from tests.shared_data import DRIVE_BOULDER, require


def test_rpy_dcm_elementary_rotations():
    # yaw 90°: sensor x (forward) becomes body y
    np.testing.assert_allclose(rpy_dcm(0, 0, 90) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    # roll 90°: sensor y becomes body z
    np.testing.assert_allclose(rpy_dcm(90, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    # pitch 90°: sensor z becomes body x
    np.testing.assert_allclose(rpy_dcm(0, 90, 0) @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    # the order is Rz Ry Rx
    r, p, y = 10.0, -20.0, 30.0
    np.testing.assert_allclose(rpy_dcm(r, p, y),
                               rpy_dcm(0, 0, y) @ rpy_dcm(0, p, 0) @ rpy_dcm(r, 0, 0))


@pytest.mark.parametrize("angles", [(180, 0, 180), (0, -6.79, 5.35), (33, 44, -55)])
def test_mounting_matrix_is_a_rotation(angles):
    for frame in ("RFU", "FRD"):
        c = mounting_matrix(axes_matrix(("-y", "x", "z")), angles, (1, 2, 3), frame)
        np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(c) == pytest.approx(1.0)


def test_frd_to_rfu_and_composition_order():
    assert np.linalg.det(FRD_TO_RFU) == pytest.approx(1.0)
    # FRD forward/right/down → RFU right/forward/up
    np.testing.assert_allclose(FRD_TO_RFU @ [1, 2, 3], [2, 1, -3])
    ax = axes_matrix(("y", "-x", "z"))
    c = mounting_matrix(ax, (180, 0, 180), (0, -6.79, 5.35), "FRD")
    np.testing.assert_allclose(c, FRD_TO_RFU @ rpy_dcm(0, -6.79, 5.35) @ rpy_dcm(180, 0, 180)
                               @ ax)
    # [180, 0, 180]: x → −x, y → y, z → −z
    np.testing.assert_allclose(rpy_dcm(180, 0, 180), np.diag([-1.0, 1.0, -1.0]), atol=1e-15)


@pytest.fixture(scope="module")
def drive():
    require(DRIVE_BOULDER)
    from pathlib import Path

    from gmis.readers import load_dataset
    from gmis.recipe import load_recipe
    root = Path(__file__).resolve().parents[1]
    return load_dataset(load_recipe(root / "datasets/drive-boulder-0708/recipe.toml"))


def test_real_drive_stationary_specific_force_points_up(drive):
    imu = drive.imu
    still = imu.t < imu.t[0] + 30.0  # parked for the first ~34 s
    f = imu.accel[still].mean(axis=0)
    assert f[2] == pytest.approx(9.93, abs=0.05)  # ≈ +g on body up (norm 1.013 g)
    tilt_deg = np.degrees(np.arccos(f[2] / np.linalg.norm(f)))
    assert tilt_deg < 3.0  # level within the car's parked tilt (measured 1.8°)
    # the sensor's x reads +0.118 g at rest; the −6.79° misalignment pitch levels it
    assert abs(f[1]) < 0.1


def test_real_drive_gyro_turn_matches_gnss_course_rate(drive):
    imu, gnss = drive.imu, drive.gnss
    still = imu.t < imu.t[0] + 30.0
    bz = imu.gyro[still, 2].mean()
    speed = np.hypot(gnss.vel_enu[:, 0], gnss.vel_enu[:, 1])
    course = np.unwrap(np.arctan2(gnss.vel_enu[:, 0], gnss.vel_enu[:, 1]))
    course_rate = np.gradient(course, gnss.t)  # azimuth rate, clockwise positive
    yaw = np.r_[0.0, np.cumsum((imu.gyro[1:, 2] - bz) * np.diff(imu.t))]
    gyro_rate = np.gradient(np.interp(gnss.t, imu.t, yaw), gnss.t)  # about up, CCW +
    moving = (speed > 3.0) & (gnss.t > imu.t[0]) & (gnss.t < imu.t[-1])
    x, y = -course_rate[moving], gyro_rate[moving]
    assert moving.sum() > 1000
    slope = float(x @ y / (x @ x))
    assert slope == pytest.approx(1.0, abs=0.03)  # measured 0.992
    assert np.corrcoef(x, y)[0, 1] > 0.99  # measured 0.996
