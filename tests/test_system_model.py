"""Φ and Λ against central finite differences of f (001 eq. 5.1.1/5.1.2), at random
states including turns, banked turns and pitched attitudes."""

import numpy as np
import pytest

from gmis.system_model import propagate_state, transition_jacobians


def random_state(rng, n):
    x = np.zeros(n)
    x[0:3] = rng.normal(0, 500, 3)
    x[3:6] = rng.normal(0, 8, 3)
    x[6:9] = rng.normal(0, 2, 3)
    x[9] = rng.uniform(-0.4, 0.4)
    x[10] = rng.uniform(-0.5, 0.5)
    x[11] = rng.uniform(0, 2 * np.pi)
    x[12:15] = rng.normal(0, 0.5, 3)
    x[15:] = rng.normal(0, 1e-2, n - 15)
    return x


def central_difference(fun, x0, step):
    cols = []
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = step[i]
        cols.append((fun(x0 + e) - fun(x0 - e)) / (2 * step[i]))
    return np.array(cols).T


@pytest.mark.parametrize("n", [21, 27])
@pytest.mark.parametrize("dt", [0.005, 0.01, 0.2])
def test_phi_and_lambda_match_central_differences(n, dt):
    rng = np.random.default_rng(1234 + n)
    nw = n - 9
    for _ in range(20):
        x = random_state(rng, n)
        phi, lam = transition_jacobians(x, dt)
        zero_w = np.zeros(nw)
        phi_fd = central_difference(lambda xx, w=zero_w: propagate_state(xx, w, dt, n), x,
                                    np.full(n, 1e-6))
        lam_fd = central_difference(lambda ww, x0=x: propagate_state(x0, ww, dt, n), zero_w,
                                    np.full(nw, 1e-3))
        assert np.linalg.norm(phi - phi_fd) / np.linalg.norm(phi) < 1e-6
        assert np.abs(phi - phi_fd).max() < 1e-6
        assert np.linalg.norm(lam - lam_fd) / np.linalg.norm(lam) < 1e-6


def _turn_step_error(dt):
    speed, rate = 10.0, 0.3
    x = np.zeros(21)
    x[4] = speed                      # forward
    x[6] = -rate * speed              # centripetal acceleration a^b = C_n^b r'' (to the left)
    x[14] = rate                      # yaw rate about up: a left turn
    y = propagate_state(x, np.zeros(12), dt, 21)
    radius = speed / rate
    ang = rate * dt
    exact = np.array([-radius * (1 - np.cos(ang)), radius * np.sin(ang)])
    assert abs(y[11] - (-ang)) < 1e-12          # azimuth decreases in a left turn
    return np.hypot(*(y[0:2] - exact))


def test_position_is_second_order_on_an_exact_turn():
    """Constant-speed level turn: the one-step position error of f is the neglected
    third-order term |C j| Δt³/6 with j = ω×a (= v ω² Δt³/6), so it falls 8× per halving."""
    e1, e2 = _turn_step_error(0.01), _turn_step_error(0.005)
    assert e1 < 1.01 * 10.0 * 0.3 ** 2 * 0.01 ** 3 / 6
    assert 7.5 < e1 / e2 < 8.5
