"""Tightly coupled DD measurement Jacobians against central finite differences."""

import numpy as np
import pytest

from gmis.tc_models import (
    OBS_CODE,
    OBS_DOPPLER,
    OBS_L1,
    OBS_L2,
    antenna_ecef,
    dd_model_and_jacobian,
    tdcp_model_and_jacobian,
)
from tests.test_system_model import FRAME, LEVER, central_difference, random_state


def scene(rng, n_sats=6, n_amb=2 * 6):
    x = random_state(rng, 27 + n_amb)
    x[27:] = rng.integers(-1000, 1000, n_amb) + rng.normal(0, 0.1, n_amb)
    r_ant, _ = antenna_ecef(x, LEVER, FRAME)
    up = r_ant / np.linalg.norm(r_ant)
    sats = []
    while len(sats) < n_sats:
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        if d @ up > 0.3:
            sats.append(r_ant + 2.2e7 * d)
    sat_pos = np.array(sats)
    sat_vel = rng.normal(0, 3000, (n_sats, 3))
    base_range = np.linalg.norm(sat_pos - FRAME[3:6], axis=1)
    base_rate = rng.normal(0, 500, n_sats)
    amb = np.vstack([27 + np.arange(n_sats), 27 + n_sats + np.arange(n_sats)])
    return x, sat_pos, sat_vel, base_range, base_rate, amb


def test_dd_jacobian_matches_central_differences():
    rng = np.random.default_rng(2)
    lam = np.array([0.190293672798, 0.244210213425])
    for _ in range(10):
        x, sp, sv, br, bv, amb = scene(rng)
        ref = 0
        ks = np.arange(1, 6)
        kinds = np.repeat([OBS_CODE, OBS_L1, OBS_L2, OBS_DOPPLER], ks.size)
        sat_k = np.tile(ks, 4)
        sat_j = np.zeros_like(sat_k) + ref

        def h_of(xx, scene_args=(kinds, sat_k, sat_j, sp, sv, br, bv, amb, lam)):
            return dd_model_and_jacobian(xx, *scene_args, LEVER, FRAME)[0]
        _, jac = dd_model_and_jacobian(x, kinds, sat_k, sat_j, sp, sv, br, bv, amb, lam,
                                       LEVER, FRAME)
        # ranges are ~2e7 m, so each evaluation carries ~4e-9 m of rounding: steps large
        # enough to keep it below the tolerance, small enough for truncation (≤ 3e-7)
        step = np.full(x.size, 1e-3)
        step[0:3] = 1e-2
        fd = central_difference(h_of, x, step)
        assert np.linalg.norm(jac - fd) / np.linalg.norm(jac) < 1e-6
        assert np.abs(jac - fd).max() < 1e-5


def test_dd_prediction_at_truth_reproduces_geometry():
    rng = np.random.default_rng(3)
    x, sp, sv, br, bv, amb = scene(rng)
    r_ant, _ = antenna_ecef(x, LEVER, FRAME)
    rho = np.linalg.norm(sp - r_ant, axis=1)
    lam = np.array([0.19, 0.244])
    h, _ = dd_model_and_jacobian(x, np.array([OBS_L1]), np.array([3]), np.array([1]), sp, sv,
                                 br, bv, amb, lam, LEVER, FRAME)
    expect = (rho[3] - br[3]) - (rho[1] - br[1]) + lam[0] * (x[amb[0, 3]] - x[amb[0, 1]])
    assert abs(h[0] - expect) < 1e-3


def five_point_difference(fun, x0, step):
    cols = []
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = step[i]
        cols.append((-fun(x0 + 2 * e) + 8 * fun(x0 + e) - 8 * fun(x0 - e) + fun(x0 - 2 * e))
                    / (12 * step[i]))
    return np.array(cols).T


@pytest.mark.parametrize("n_imu", [21, 27])
@pytest.mark.parametrize("dt", [0.2, 0.5, 30.0])
def test_tdcp_jacobian_matches_central_differences(n_imu, dt):
    """Random states with turns, bank and pitch (random_state: |pitch| ≤ 0.4, |roll| ≤ 0.5
    rad, ω ~ 0.5 rad/s per axis), satellites moving between the two epochs."""
    rng = np.random.default_rng(7 + n_imu + int(10 * dt))
    for _ in range(8):
        x, sp, sv, br, _, _ = scene(rng)
        x = x[:n_imu].copy()
        prev_sp = sp - sv * dt
        prev_br = br - rng.normal(0, 500, br.size) * dt
        ks = np.arange(1, 6)
        js = np.zeros_like(ks)

        def h_of(xx, scene_args=(dt, ks, js, sp, br, prev_sp, prev_br)):
            return tdcp_model_and_jacobian(xx, *scene_args, LEVER, FRAME)[0]
        _, jac = tdcp_model_and_jacobian(x, dt, ks, js, sp, br, prev_sp, prev_br, LEVER,
                                        FRAME)
        # h is a difference of four ~2e7 m ranges (~1e-8 m rounding): the fourth-order
        # stencil allows steps large enough to keep rounding/step below 1e-6; v, a, ω act
        # through vΔt, aΔt²/2, ωΔt, so their steps shrink with Δt
        step = np.full(x.size, 2e-2)
        for sl in (slice(3, 9), slice(12, 15)):
            step[sl] /= max(1.0, dt)
        fd = five_point_difference(h_of, x, step)
        assert np.linalg.norm(jac - fd) / np.linalg.norm(jac) < 1e-6
        assert np.all(np.abs(jac - fd) <= 2e-6 * (1.0 + np.abs(jac).max(axis=0)))
        assert np.all(jac[:, 15:] == 0.0)


def test_tdcp_prediction_is_the_difference_of_the_two_epochs_geometry():
    """A steady circular turn (0.25 rad/s, 12 m/s, banked): with ĵ = ω×a the state at t_k
    predicts the antenna position at t_k − Δt to 4th order, so h equals the DD range
    difference of the true antenna positions of both epochs within 1 mm (without ĵ the
    error would be ~1.5 cm)."""
    from gmis.frames import dcm_body_to_nav
    rng = np.random.default_rng(11)
    x, sp, sv, br, _, _ = scene(rng)
    speed, rate, roll, dt = 12.0, 0.25, 0.05, 0.5
    x = x[:21].copy()
    x[9], x[10] = 0.0, roll
    # turn about the navigation up axis at heading rate −rate (ψ clockwise, ω_z body up)
    c = dcm_body_to_nav(0.0, roll, x[11])
    om_n = np.array([0.0, 0.0, rate])
    x[12:15] = c.T @ om_n
    x[3:6] = np.array([0.0, speed, 0.0])
    x[6:9] = np.cross(x[12:15], x[3:6])
    c_ne = FRAME[6:15].reshape(3, 3).T

    def antenna(tau):            # exact position at t_k + tau on the circle
        ang = rate * tau
        rot = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0],
                        [0, 0, 1]])
        v_n = c @ x[3:6]
        centre = x[0:3] + np.cross(om_n, v_n) / (rate * rate)
        r = centre + rot @ (x[0:3] - centre)
        return FRAME[3:6] + c_ne @ (r + rot @ c @ LEVER)

    prev_sp = sp - sv * dt
    prev_br = br + 3.0
    r_now, r_prev = antenna(0.0), antenna(-dt)
    rho_now = np.linalg.norm(sp - r_now, axis=1)
    rho_prev = np.linalg.norm(prev_sp - r_prev, axis=1)
    expect = ((rho_now[3] - br[3]) - (rho_now[1] - br[1])) \
        - ((rho_prev[3] - prev_br[3]) - (rho_prev[1] - prev_br[1]))
    h, _ = tdcp_model_and_jacobian(x, dt, np.array([3]), np.array([1]), sp, br, prev_sp,
                                   prev_br, LEVER, FRAME)
    assert abs(antenna(0.0) - antenna_ecef(x, LEVER, FRAME)[0]).max() < 1e-9
    assert abs(h[0] - expect) < 1e-3
