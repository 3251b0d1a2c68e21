"""Φ and Λ against central finite differences of f (001 eq. 5.1.1/5.1.2), at random
states including turns, banked turns and pitched attitudes."""

import numpy as np
import pytest

from gmis.earth import make_nav_frame
from gmis.system_model import propagate_state, transition_jacobians

# the navigation frame and body lever arm (m) of the measurement-model Jacobian tests
FRAME = make_nav_frame(np.radians(43.77), np.radians(-79.50), 180.0)
LEVER = np.array([0.3, 1.0, 1.5])


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


@pytest.mark.parametrize("n", [21, 27])
@pytest.mark.parametrize("dt", [0.01, 0.2])
def test_gauss_markov_phi_matches_central_differences(n, dt):
    """Φ with Gauss-Markov drift states (b' = e^{−Δt/τ} b + w) against central differences
    of f; some drift states stay random walks (1/τ = 0)."""
    rng = np.random.default_rng(77 + n)
    nw = n - 9
    for _ in range(10):
        x = random_state(rng, n)
        inv_tau = rng.uniform(0.0, 2.0, n - 15) * (rng.random(n - 15) < 0.7)
        phi, lam = transition_jacobians(x, dt, inv_tau)
        zero_w = np.zeros(nw)
        phi_fd = central_difference(
            lambda xx, w=zero_w, it=inv_tau: propagate_state(xx, w, dt, n, it), x, np.full(n, 1e-6))
        lam_fd = central_difference(
            lambda ww, x0=x, it=inv_tau: propagate_state(x0, ww, dt, n, it), zero_w, np.full(nw, 1e-3))
        assert np.abs(phi - phi_fd).max() < 1e-6
        assert np.linalg.norm(lam - lam_fd) / np.linalg.norm(lam) < 1e-6
        drift = np.diag(phi)[15:]
        assert np.allclose(drift, np.exp(-dt * inv_tau), rtol=0, atol=1e-14)


def test_drift_noise_variance_gauss_markov_and_random_walk_limit():
    from gmis.system_model import drift_noise_variance
    sigma, tau, dt = 3e-4, 50.0, 0.01
    q = 2 * sigma ** 2 / tau
    assert drift_noise_variance(q, dt, 1 / tau) == pytest.approx(
        sigma ** 2 * (1 - np.exp(-2 * dt / tau)), rel=1e-12)
    assert drift_noise_variance(q, dt, 0.0) == q * dt
    assert drift_noise_variance(q, dt, 1e-9) == pytest.approx(q * dt, rel=1e-8)


def _kernel_predict(x, p, dt, q_psd, inv_tau, n_imu, steps=1):
    from gmis.gmikf import make_workspace, predict
    ws = make_workspace(x.shape[0], q_psd.shape[0])
    for _ in range(steps):
        predict(x, p, dt, n_imu, q_psd, 1.0, False, ws, inv_tau)


@pytest.mark.parametrize("n", [21, 27])
def test_kernel_prediction_with_gauss_markov_equals_dense_formula(n):
    """The GMIKF's predict (in-place Φ P Φᵀ, decay, Λ Q Λᵀ) against the dense
    Φ P Φᵀ + Λ Q Λᵀ with Φ from transition_jacobians and Q of discrete_process_noise."""
    from gmis.gmikf import discrete_process_noise
    rng = np.random.default_rng(5 + n)
    x = random_state(rng, n)
    a = rng.normal(size=(n, n))
    p = a @ a.T / n + np.eye(n)
    q_psd = rng.uniform(0.1, 2.0, n - 9) * 1e-3
    inv_tau = np.array([0.0, 0.02, 0.5] + [0.1] * (n - 18))
    dt = 0.05
    phi, _ = transition_jacobians(x, dt, inv_tau)
    x_ref = propagate_state(x, np.zeros(n - 9), dt, n, inv_tau)
    p_ref = phi @ p @ phi.T + discrete_process_noise(x, dt, q_psd, n, drift_inv_tau=inv_tau)
    xk, pk = x.copy(), p.copy()
    _kernel_predict(xk, pk, dt, q_psd, inv_tau, n)
    assert np.allclose(xk, x_ref, rtol=1e-13, atol=1e-12)
    assert np.allclose(pk, p_ref, rtol=1e-12, atol=1e-14)


def test_kernel_gauss_markov_bias_variance_reaches_sigma2():
    """Predicting only, a Gauss-Markov bias of σ, τ settles at variance σ² whatever P0 (the
    random-walk bias keeps growing as q t)."""
    sigma, tau, dt, n = 2e-3, 20.0, 0.01, 21
    x = np.zeros(n)
    p = np.eye(n) * 1e-12
    p[15, 15] = (10 * sigma) ** 2
    q_psd = np.zeros(n - 9)
    q_psd[6] = 2 * sigma ** 2 / tau            # b_ω x: Gauss-Markov
    q_psd[7] = 2 * sigma ** 2 / tau            # b_ω y: random walk, same density
    inv_tau = np.zeros(6)
    inv_tau[0] = 1 / tau
    _kernel_predict(x, p, dt, q_psd, inv_tau, n, steps=int(10 * tau / dt))
    assert p[15, 15] == pytest.approx(sigma ** 2, rel=1e-3)
    assert p[16, 16] == pytest.approx(q_psd[7] * 10 * tau, rel=1e-9)
