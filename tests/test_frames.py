"""Convention tests (docs/DESIGN.md): C_b^n from Euler angles vs Euler-rate integration vs
DCM propagation with the same ω; Euler round trip; ENU↔geodetic against pymap3d."""

import numpy as np
import pymap3d
import pytest

from gmis.earth import (
    ecef_to_geodetic,
    enu_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
    make_nav_frame,
    normal_gravity,
)
from gmis.frames import (
    dcm_body_to_nav,
    euler_from_dcm,
    euler_rate_matrix,
    rotation_vector_to_dcm,
    skew,
)


def omega_of_t(t):
    """A smooth body rate history (rad/s) with roll, pitch and yaw motion."""
    return np.array([0.2 * np.sin(0.7 * t), 0.15 * np.cos(0.5 * t), 0.3 * np.sin(0.3 * t + 1)])


def test_forward_axis_and_heading_convention():
    c = dcm_body_to_nav(0.0, 0.0, np.radians(90.0))
    np.testing.assert_allclose(c @ [0, 1, 0], [1, 0, 0], atol=1e-15)   # heading 90° = east
    c = dcm_body_to_nav(np.radians(10.0), 0.0, 0.0)
    assert (c @ [0, 1, 0])[2] > 0                                       # pitch up: nose up
    c = dcm_body_to_nav(0.0, np.radians(10.0), 0.0)
    assert (c @ [1, 0, 0])[2] < 0                                       # roll +: right side down
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-15)
    assert np.isclose(np.linalg.det(c), 1.0)


def test_euler_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(200):
        th = np.array([rng.uniform(-1.4, 1.4), rng.uniform(-3.1, 3.1), rng.uniform(0, 6.28)])
        np.testing.assert_allclose(euler_from_dcm(dcm_body_to_nav(*th)), th, atol=1e-12)


def test_euler_rate_integration_agrees_with_dcm_propagation():
    """θ̇ = C(θ)ω (eq. 2.2.6) integrated with RK4 and Ċ = C[ω×] (eq. 2.2.2) propagated with
    exact rotation-vector steps from the same ω(t) give the same attitude."""
    th = np.array([0.05, -0.1, 1.0])
    c = dcm_body_to_nav(*th)
    dt, n = 0.001, 20000
    for k in range(n):
        t = k * dt
        f = lambda tt, x: euler_rate_matrix(x[0], x[1]) @ omega_of_t(tt)
        k1 = f(t, th)
        k2 = f(t + dt / 2, th + dt / 2 * k1)
        k3 = f(t + dt / 2, th + dt / 2 * k2)
        k4 = f(t + dt, th + dt * k3)
        th = th + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        # second-order rotation vector over the step (coning-free for a smooth ω)
        w0, w1, wm = omega_of_t(t), omega_of_t(t + dt), omega_of_t(t + dt / 2)
        phi = dt / 6 * (w0 + 4 * wm + w1) + dt ** 2 / 12 * np.cross(w0, w1)
        c = c @ rotation_vector_to_dcm(phi)
    c_euler = dcm_body_to_nav(*th)
    assert np.abs(c_euler - c).max() < 1e-9
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-12)


def test_dcm_derivative_is_c_times_skew_omega():
    th = np.array([0.2, -0.3, 2.0])
    w = np.array([0.1, -0.2, 0.3])
    h = 1e-6
    th_dot = euler_rate_matrix(th[0], th[1]) @ w
    c_dot = (dcm_body_to_nav(*(th + h * th_dot)) - dcm_body_to_nav(*(th - h * th_dot))) / (2 * h)
    np.testing.assert_allclose(c_dot, dcm_body_to_nav(*th) @ skew(w), atol=1e-9)


@pytest.mark.parametrize("lat0, lon0, h0", [(43.77, -79.50, 180.0), (-33.9, 151.2, 40.0),
                                            (78.2, 15.6, 10.0), (0.0, 0.0, 0.0)])
def test_enu_geodetic_round_trip_and_pymap3d(lat0, lon0, h0):
    frame = make_nav_frame(np.radians(lat0), np.radians(lon0), h0)
    rng = np.random.default_rng(1)
    for _ in range(50):
        enu = rng.normal(0, 5000, 3)
        enu[2] = rng.normal(0, 100)
        lat, lon, h = enu_to_geodetic(frame, enu)
        back = geodetic_to_enu(frame, lat, lon, h)
        np.testing.assert_allclose(back, enu, atol=1e-7)
        ref = pymap3d.enu2geodetic(*enu, lat0, lon0, h0)
        assert abs(np.degrees(lat) - ref[0]) < 1e-10
        assert abs(np.degrees(lon) - ref[1]) < 1e-10
        assert abs(h - ref[2]) < 1e-6
    xyz = geodetic_to_ecef(np.radians(lat0), np.radians(lon0), h0)
    np.testing.assert_allclose(xyz, pymap3d.geodetic2ecef(lat0, lon0, h0), atol=1e-6)
    lat, lon, h = ecef_to_geodetic(*xyz)
    assert abs(np.degrees(lat) - lat0) < 1e-11 and abs(h - h0) < 1e-6


def test_normal_gravity_reference_values():
    # WGS84 normal gravity at the equator and the pole on the ellipsoid (NIMA TR8350.2)
    assert abs(normal_gravity(0.0, 0.0) - 9.7803253359) < 1e-9
    assert abs(normal_gravity(np.pi / 2, 0.0) - 9.8321849378) < 1e-8
    # free-air gradient ≈ −0.3086 mGal/m
    assert abs((normal_gravity(0.8, 100.0) - normal_gravity(0.8, 0.0)) / 100 + 3.086e-6) < 2e-8
