"""Process noise from Δt (issue 13 item 1): the GMIKF builds each prediction's Q from its
own Δt out of spectral densities (GmikfConfig.q_psd), so the random-walk parts (a^b, ω,
biases, scale factors) accumulate q·T whatever the epochs in between — an off-grid aiding
epoch or an IMU gap — and a step of the nominal 0.01 s gives back 001's per-step Q."""

import math

import numpy as np
import pytest

from gmis.earth import make_nav_frame
from gmis.epochs import EpochIndex
from gmis.gmikf import discrete_process_noise
from gmis.run_filter import GmikfConfig, GmikfRunner, Measurements
from gmis.state import I_ACC, I_ATT, I_BG, I_POS, I_RATE, I_VEL, N_DYNAMIC, N_STATES_27
from gmis.system_model import transition_jacobians

FRAME = make_nav_frame(math.radians(43.77), math.radians(-79.50), 180.0)
Q_SD = np.array([72.0, 72.0, 72.0, 5.2, 5.2, 5.2, *([1e-6] * 3), *([1e-5] * 3),
                 *([1e-7] * 3), *([1e-7] * 3)])   # per step at 100 Hz (001 Table 6-2 shape)
RANDOM_WALK = [*range(I_ACC, I_ACC + 3), *range(I_RATE, I_RATE + 3),
               *range(N_DYNAMIC, N_STATES_27)]


def _config():
    return GmikfConfig(n_imu=N_STATES_27, q_sd=Q_SD, imu_sd=np.full(6, 1e-3),
                       lever_arm=np.zeros(3), p0_sd=np.zeros(N_STATES_27),
                       outlier_alpha=0.0)


def _at_rest():
    """Level, at rest, no rotation: the step model is linear and time-invariant."""
    return np.zeros(N_STATES_27)


def test_nominal_step_is_the_per_step_model():
    """q_sd are per-step values at 100 Hz: a 0.01 s step adds Λ diag(q_sd²) Λᵀ."""
    x = _at_rest()
    x[I_VEL:I_VEL + 3] = [0.1, 12.0, 0.0]
    x[I_RATE:I_RATE + 3] = [0.01, 0.0, 0.3]
    _, lam = transition_jacobians(x, 0.01)
    expect = lam @ np.diag(Q_SD ** 2) @ lam.T
    got = discrete_process_noise(x, 0.01, _config().q_psd(), N_STATES_27)
    scale = np.sqrt(np.outer(np.diag(expect), np.diag(expect)))   # rounding of Σ terms
    assert np.all(np.abs(got - expect) <= 1e-12 * scale)
    assert np.all(np.abs(np.diag(got) - np.diag(expect)) <= 1e-12 * np.diag(expect))


def test_random_walks_grow_with_time_not_with_steps():
    q = _config().q_psd()
    for dt in (0.005, 0.0137, 0.05):
        qd = discrete_process_noise(_at_rest(), dt, q, N_STATES_27)
        for k in range(3):
            assert qd[I_ACC + k, I_ACC + k] == pytest.approx(q[k] * dt, rel=1e-12)
            assert qd[I_RATE + k, I_RATE + k] == pytest.approx(q[3 + k] * dt, rel=1e-12)
            assert qd[I_BG + k, I_BG + k] == pytest.approx(q[6 + k] * dt, rel=1e-12)


def _predicted_p(times):
    """P after predicting from P0 = 0 through the epochs `times` with no measurement (the
    kernel path: every epoch is an aiding-only epoch without data)."""
    t = np.asarray(times, float)
    none = np.full(t.size, -1, dtype=np.int64)
    epochs = EpochIndex(t=t, imu=none, pos=none, vel=none, heading=none)
    runner = GmikfRunner(epochs, Measurements(imu_z=np.zeros((0, 6))), _at_rest(),
                         _config(), FRAME)
    runner.advance(t.size)
    return runner.p


def _block(p, idx):
    return p[np.ix_(idx, idx)]


@pytest.mark.parametrize("times", [
    [0.0, 0.0037, 0.01],                 # an off-grid GNSS epoch inside an IMU interval
    [0.0, 0.01, 0.0100004, 0.02],        # one 0.4 µs after an IMU epoch
    [0.0, 0.05],                         # a 50 ms IMU dropout in one step
])
def test_split_or_gap_keeps_the_random_walk_covariance(times):
    """The a^b, ω, bias and scale-factor block equals the continuous q·T of one step from
    the first to the last epoch, however the interval is cut (no double counting)."""
    p = _predicted_p(times)
    q = _config().q_psd()
    total = times[-1] - times[0]
    expect = np.diag(np.concatenate([q[:6], q[6:]]) * total)
    np.testing.assert_allclose(_block(p, RANDOM_WALK), expect, rtol=1e-10, atol=1e-30)


def test_integrated_states_between_held_and_white_noise():
    """v^b from jerk and θ from ω̇: N equal steps of h over T give the analytic variance of
    the integral of a piecewise-linear random walk, q (T³/3 − T h²/12): T³/4 for one step
    (the held-noise value), → T³/3 (white noise) as h → 0."""
    q = _config().q_psd()
    total = 0.06
    for n in (1, 2, 3, 6):
        p = _predicted_p(np.linspace(0.0, total, n + 1))
        h = total / n
        want_v = q[0] * (total ** 3 / 3 - total * h * h / 12)
        want_t = q[3] * (total ** 3 / 3 - total * h * h / 12)
        for k in range(3):
            assert p[I_VEL + k, I_VEL + k] == pytest.approx(want_v, rel=1e-9), (n, k)
            assert p[I_ATT + k, I_ATT + k] == pytest.approx(want_t, rel=1e-9), (n, k)
        assert p[I_POS, I_POS] > 0
