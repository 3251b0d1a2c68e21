"""IMU and loosely coupled measurement Jacobians against central finite differences, and
the IMU model against the shared simulator model (gmis.imu_model)."""

import numpy as np
import pytest

from gmis.imu_model import imu_measurement
from gmis.measurement_models import (
    gnss_position_model_and_jacobian_into,
    gnss_velocity_model_and_jacobian_into,
    heading_model_and_jacobian_into,
    imu_model_and_jacobian_into,
    nonholonomic_model_and_jacobian_into,
)
from tests.test_system_model import FRAME, LEVER, central_difference, random_state


def _model(fun, n_rows):
    def h(x):
        out = np.zeros(n_rows)
        jac = np.zeros((n_rows, x.size))
        fun(x, out, jac)
        return out
    return h


def _jac(fun, n_rows, x):
    out = np.zeros(n_rows)
    jac = np.zeros((n_rows, x.size))
    fun(x, out, jac)
    return jac


CASES = {
    "imu": (lambda n: (lambda x, o, j: imu_model_and_jacobian_into(x, n, FRAME, o, 0, j, 0)), 6),
    "position": (lambda n: (lambda x, o, j: gnss_position_model_and_jacobian_into(
        x, LEVER, o, 0, j, 0)), 3),
    "velocity": (lambda n: (lambda x, o, j: gnss_velocity_model_and_jacobian_into(
        x, LEVER, o, 0, j, 0)), 3),
    "heading": (lambda n: (lambda x, o, j: heading_model_and_jacobian_into(x, o, 0, j, 0)), 1),
    "nonholonomic": (lambda n: (lambda x, o, j: nonholonomic_model_and_jacobian_into(
        x, np.array([0.2, -1.4, -0.6]), o, 0, j, 0)), 2),
}


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("n", [21, 27])
def test_measurement_jacobian_matches_central_differences(name, n):
    make, rows = CASES[name]
    fun = make(n)
    rng = np.random.default_rng(7)
    for _ in range(20):
        x = random_state(rng, n)
        x[0:3] = rng.normal(0, 3000, 3)   # km-scale positions exercise the gravity gradient
        jac = _jac(fun, rows, x)
        step = np.full(n, 1e-6)
        step[0:3] = 1e-2                  # gravity varies on km scales: larger position step
        fd = central_difference(_model(fun, rows), x, step)
        assert np.linalg.norm(jac - fd) / np.linalg.norm(jac) < 1e-6, name
        assert np.abs(jac - fd).max() < 1e-6, name


def test_filter_imu_model_equals_simulator_model():
    rng = np.random.default_rng(3)
    for _ in range(10):
        x = random_state(rng, 27)
        out = np.zeros(6)
        imu_model_and_jacobian_into(x, 27, FRAME, out, 0, np.zeros((6, 27)), 0)
        ref = imu_measurement(x[0:3], x[3:6], x[6:9], x[9:12], x[12:15], x[15:18],
                              x[18:21], x[21:24], x[24:27], FRAME)
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)


def test_nonholonomic_model_is_the_lateral_and_vertical_velocity_of_the_constraint_point():
    """h = [(v + ω×l)_x, (v + ω×l)_z]: compared with numpy's cross product."""
    rng = np.random.default_rng(3)
    lever = np.array([0.2, -1.4, -0.6])
    for _ in range(5):
        x = random_state(rng, 27)
        out = np.zeros(2)
        nonholonomic_model_and_jacobian_into(x, lever, out, 0, np.zeros((2, 27)), 0)
        u = x[3:6] + np.cross(x[12:15], lever)
        assert np.allclose(out, u[[0, 2]], rtol=0, atol=1e-12)


def test_baseline_heading_jacobian_and_model():
    """Attitude-aware dual-antenna heading row (gmis.measurement_models module doc):
    Jacobian against central differences (wrapped), h = ψ for a level vehicle and for an
    unknown (zero) baseline, and h equals gnss.heading's level-vehicle conversion ψ_b − α
    of the baseline the state's attitude produces (so that ψ_b − α − h = 0 for a tilted
    vehicle, where ψ_b − α − ψ is not)."""
    from gmis.frames import dcm_body_to_nav
    from gmis.measurement_models import baseline_heading_model_and_jacobian_into
    from gnss.heading import baseline_to_heading, body_baseline_azimuth
    rng = np.random.default_rng(11)
    prim, sec = np.array([0.3, 1.0, 1.5]), np.array([-0.9, 0.2, 1.7])
    base = sec - prim
    alpha = body_baseline_azimuth(prim, sec)

    def run(x, baseline):
        out, jac = np.zeros(1), np.zeros((1, x.size))
        baseline_heading_model_and_jacobian_into(x, baseline, out, 0, jac, 0)
        return out[0], jac[0]
    for n in (21, 27):
        for _ in range(20):
            x = random_state(rng, n)
            x[9:11] = np.radians(rng.uniform(-20, 20, 2))
            h0, jac = run(x, base)
            fd = np.zeros(n)
            for k in range(n):
                e = np.zeros(n)
                e[k] = 1e-6
                d = run(x + e, base)[0] - run(x - e, base)[0]
                fd[k] = ((d + np.pi) % (2 * np.pi) - np.pi) / 2e-6
            assert np.abs(jac - fd).max() < 1e-7
            assert jac[11] == pytest.approx(1.0, abs=1e-12)
            # the level-vehicle conversion of the baseline this attitude produces
            b = dcm_body_to_nav(x[9], x[10], x[11]) @ base
            _, _, level, _, _ = baseline_to_heading(b[None], np.full((1, 3), 1e-3), alpha)
            assert abs((level[0] - h0 + np.pi) % (2 * np.pi) - np.pi) < 1e-12
            # an unknown baseline: ψ
            hz, jz = run(x, np.zeros(3))
            assert hz == x[11] and jz[11] == 1.0 and np.count_nonzero(jz) == 1
            # a level vehicle: ψ exactly
            xl = x.copy()
            xl[9:11] = 0.0
            assert abs((run(xl, base)[0] - x[11] + np.pi) % (2 * np.pi) - np.pi) < 1e-12
    x[9:11] = np.radians([8.0, -6.0])
    assert abs((run(x, base)[0] - x[11] + np.pi) % (2 * np.pi) - np.pi) > 1e-3
