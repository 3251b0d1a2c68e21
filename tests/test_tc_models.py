"""Tightly coupled DD measurement Jacobians against central finite differences."""

import numpy as np

from gmis.earth import make_nav_frame
from gmis.tc_models import (
    OBS_CODE,
    OBS_DOPPLER,
    OBS_L1,
    OBS_L2,
    antenna_ecef,
    dd_model_and_jacobian,
)
from tests.test_system_model import central_difference, random_state

FRAME = make_nav_frame(np.radians(43.77), np.radians(-79.50), 180.0)
LEVER = np.array([0.3, 1.0, 1.5])


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

        def h_of(xx):
            return dd_model_and_jacobian(xx, kinds, sat_k, sat_j, sp, sv, br, bv, amb, lam,
                                         LEVER, FRAME)[0]
        h, jac = dd_model_and_jacobian(x, kinds, sat_k, sat_j, sp, sv, br, bv, amb, lam,
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
    r_ant, v_ant = antenna_ecef(x, LEVER, FRAME)
    rho = np.linalg.norm(sp - r_ant, axis=1)
    lam = np.array([0.19, 0.244])
    h, _ = dd_model_and_jacobian(x, np.array([OBS_L1]), np.array([3]), np.array([1]), sp, sv,
                                 br, bv, amb, lam, LEVER, FRAME)
    expect = (rho[3] - br[3]) - (rho[1] - br[1]) + lam[0] * (x[amb[0, 3]] - x[amb[0, 1]])
    assert abs(h[0] - expect) < 1e-6
