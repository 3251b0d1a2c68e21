"""Lock-out recovery (gmis.lockout_recovery, issue 14 item 4): an aiding group rejected at
``reopen_after`` consecutive epochs re-opens the covariance along what it observes and is
accepted again; a single outlier is still rejected."""

import math

import numpy as np
import pytest

from gmis.earth import make_nav_frame
from gmis.epochs import merge_streams
from gmis.gmikf import AIDING_GROUPS, GROUP_SIZE, GROUP_START, N_SLOTS, SLOT_POS
from gmis.lockout_recovery import inflate_along_observation, recover_lockout
from gmis.measurement_models import imu_model_and_jacobian_into
from gmis.run_filter import GmikfConfig, GmikfRunner, Measurements
from gmis.state import N_STATES_21, n_noise_for

FRAME = make_nav_frame(math.radians(43.77), math.radians(-79.50), 180.0)


def _random_pd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n) * 1e-3


@pytest.mark.parametrize("seed", range(5))
def test_inflation_makes_the_innovation_variance_cover_the_innovation(seed):
    rng = np.random.default_rng(seed)
    n = 12
    p = _random_pd(rng, n)
    h = np.zeros(n)
    h[rng.choice(n, 3, replace=False)] = rng.normal(size=3)
    r = 0.3
    d = 10.0 * math.sqrt(h @ p @ h + r)       # a 10σ innovation
    p_old = p.copy()
    var = inflate_along_observation(p, h, d, r, np.empty(n))
    assert var == pytest.approx(d * d, rel=1e-12)
    assert h @ p @ h + r == pytest.approx(d * d, rel=1e-9)
    delta = p - p_old
    w = np.linalg.eigvalsh(delta)
    assert w[-1] > 0 and np.all(w[:-1] > -1e-9 * w[-1])    # rank one, PSD
    c = (d * d - (h @ p_old @ h + r)) / (h @ h) ** 2
    assert np.allclose(delta, c * np.outer(h, h), rtol=1e-9, atol=1e-12)   # along h only
    assert np.all(np.linalg.eigvalsh(p) > 0)


def test_a_consistent_innovation_changes_nothing():
    rng = np.random.default_rng(7)
    p = _random_pd(rng, 6)
    h = np.array([1.0, 0, 0, 0, 0, 0])
    p_old = p.copy()
    d = 0.5 * math.sqrt(p[0, 0] + 0.1)
    inflate_along_observation(p, h, d, 0.1, np.empty(6))
    assert np.array_equal(p, p_old)


def _call(streak, reopened, rejected_pos, e=0, reopen_after=3):
    """recover_lockout on an epoch with the IMU and GNSS position present."""
    n = 6
    used = np.zeros(N_SLOTS, dtype=np.int64)
    used[:9] = np.r_[0:6, SLOT_POS:SLOT_POS + 3]
    rejected = np.zeros(N_SLOTS, dtype=np.int8)
    if rejected_pos:
        rejected[SLOT_POS] = 1
    h_all = np.zeros((N_SLOTS, n))
    for i in range(3):
        h_all[SLOT_POS + i, i] = 1.0
    d = np.zeros(N_SLOTS)
    d[6] = 5.0
    p = np.eye(n) * 0.01
    mask = recover_lockout(e, 9, p, reopen_after, np.ones(n), AIDING_GROUPS, GROUP_START,
                           GROUP_SIZE, used, d, h_all, np.full(N_SLOTS, 1e-4), rejected,
                           streak, reopened, np.empty(n))
    return mask, p


def test_streak_counts_consecutive_rejections_and_resets_on_acceptance():
    streak = np.zeros(5, dtype=np.int64)
    reopened = np.zeros(10, dtype=np.int8)
    assert _call(streak, reopened, True)[0] == 0
    assert _call(streak, reopened, True)[0] == 0
    assert _call(streak, reopened, False)[0] == 0      # accepted: streak back to 0
    assert streak[1] == 0
    assert _call(streak, reopened, True)[0] == 0
    assert _call(streak, reopened, True)[0] == 0
    mask, p = _call(streak, reopened, True, e=4)       # third in a row
    assert mask == 1 << 1 and reopened[4] == 1 << 1 and streak[1] == 0
    assert p[0, 0] + 1e-4 == pytest.approx(25.0)       # innovation 5 m covered
    assert p[1, 1] == pytest.approx(0.01)              # unobserved direction untouched


def _static_run(reopen_after, step_at_s=5.0, step_m=1.0, outlier_at_s=None):
    """At rest for 12 s: 100 Hz IMU (model-matched samples), 4 Hz GNSS position with a
    persistent east step of step_m from step_at_s (and one 1 m north outlier at
    outlier_at_s). Returns (runner records, GNSS times)."""
    n = N_STATES_21
    x0 = np.zeros(n)
    h = np.zeros(N_SLOTS)
    jac = np.zeros((N_SLOTS, n))
    imu_model_and_jacobian_into(x0, n, FRAME, h, 0, jac, 0)
    t_imu = np.arange(0.0, 12.0, 0.01)
    rng = np.random.default_rng(3)
    imu_sd = np.r_[np.full(3, 1e-3), np.full(3, 0.01)]
    imu_z = h[:6] + rng.normal(size=(t_imu.size, 6)) * imu_sd
    t_pos = np.arange(0.0, 12.0, 0.25) + 0.0025
    pos = rng.normal(size=(t_pos.size, 3)) * 0.01
    pos[t_pos >= step_at_s, 0] += step_m
    if outlier_at_s is not None:
        pos[np.argmin(abs(t_pos - outlier_at_s)), 1] += 1.0
    meas = Measurements(imu_z=imu_z, pos_enu=pos, pos_sd=np.full((t_pos.size, 3), 0.01))
    epochs = merge_streams(t_imu, t_pos)
    q_sd = np.r_[np.full(3, 0.5), np.full(3, 0.05), np.full(6, 1e-7)]
    assert q_sd.size == n_noise_for(n)
    p0 = np.r_[np.full(3, 0.01), np.full(3, 0.01), np.full(3, 0.01), np.full(3, 1e-3),
               np.full(3, 1e-3), np.full(3, 1e-4), np.full(3, 1e-3)]
    cfg = GmikfConfig(n_imu=n, q_sd=q_sd, imu_sd=imu_sd, lever_arm=np.zeros(3), p0_sd=p0,
                      reopen_after=reopen_after)
    runner = GmikfRunner(epochs, meas, x0, cfg, FRAME)
    runner.advance(len(epochs))
    return runner.rec, epochs


def test_without_recovery_a_position_step_locks_the_sensor_out():
    rec, epochs = _static_run(reopen_after=0)
    pos_e = epochs.pos >= 0
    after = pos_e & (rec.t > 6.0)
    assert rec.rejected[after, SLOT_POS].all()            # never accepted again
    assert abs(rec.x[-1, 0] - 1.0) > 0.5                  # does not follow the step
    assert not rec.reopened.any()


def test_recovery_re_accepts_a_persistent_step_and_reports_it():
    rec, epochs = _static_run(reopen_after=2)
    pos_e = np.flatnonzero(epochs.pos >= 0)
    assert np.count_nonzero(rec.reopened) >= 1
    t_first = rec.t[np.flatnonzero(rec.reopened)[0]]
    assert 5.0 < t_first <= 5.0 + 2 * 0.25 + 1e-9        # the second rejected epoch
    late = pos_e[rec.t[pos_e] > 7.0]
    assert not rec.rejected[late, SLOT_POS].any()         # accepted again
    assert rec.x[-1, 0] == pytest.approx(1.0, abs=0.03)   # follows the step


def test_a_single_outlier_is_still_rejected():
    rec, epochs = _static_run(reopen_after=2, step_m=0.0, outlier_at_s=6.0)
    pos_e = np.flatnonzero(epochs.pos >= 0)
    k = pos_e[np.argmin(abs(rec.t[pos_e] - 6.0025))]
    assert rec.rejected[k, SLOT_POS + 1] == 1
    assert not rec.reopened.any()
    assert abs(rec.x[-1, 1]) < 0.03
