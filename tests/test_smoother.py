"""Two-filter smoother (gmis.smoother): the exact backward step, the combination against
the information form, the spool, and Monte Carlo consistency on model-matched data."""

import numpy as np
import pytest
from scipy import stats

from gmis.reverse_step import invert_forward_step
from gmis.run_filter import GmikfConfig
from gmis.smoother import (
    StateSpool,
    combine_two_filter,
    combine_two_filter_into,
    output_epochs,
    run_two_filter,
)
from gmis.system_model import propagate_state
from tests.model_matched_sim import (
    FRAME,
    model_matched_inputs,
    model_matched_p0_sd,
    simulate_model_matched,
)


def _turning_state():
    x = np.zeros(21)
    x[3:6] = [8.0, 0.5, -0.1]
    x[6:9] = [0.5, 1.0, -0.3]
    x[9:12] = [0.05, -0.03, 6.2]
    x[12:15] = [0.05, -0.02, 0.3]
    return x


def test_backward_step_inverts_the_forward_step():
    x = _turning_state()
    y = propagate_state(x, np.zeros(12), 0.01, 21)
    back = propagate_state(y, np.zeros(12), -0.01, 21)
    assert np.abs(back - x)[9:12].max() > 1e-7      # f(·, −Δt) alone misses
    invert_forward_step(y, back, 0.01, 21, np.zeros(12), np.empty(21))
    np.testing.assert_allclose(back, x, rtol=0, atol=1e-11)


def test_combination_equals_the_information_form():
    rng = np.random.default_rng(3)
    n = 21
    a, b = rng.normal(size=(n, n)), rng.normal(size=(n, n))
    p_f, p_b = a @ a.T + 0.1 * np.eye(n), 10 * (b @ b.T) + np.eye(n)
    x_f, x_b = rng.normal(size=n), rng.normal(size=n)
    x_f[11], x_b[11] = 0.01, 2 * np.pi - 0.02          # heading across the wrap
    x_s, p_s = combine_two_filter(x_f, p_f, x_b, p_b)
    info = np.linalg.inv(p_f) + np.linalg.inv(p_b)
    x_b_unwrapped = x_b.copy()
    x_b_unwrapped[11] -= 2 * np.pi
    x_ref = np.linalg.solve(info, np.linalg.solve(p_f, x_f) + np.linalg.solve(p_b, x_b_unwrapped))
    x_ref[11] %= 2 * np.pi
    np.testing.assert_allclose(p_s, np.linalg.inv(info), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(x_s, x_ref, rtol=1e-8, atol=1e-10)
    x_c, p_c = np.empty(n), np.empty((n, n))
    assert combine_two_filter_into(x_f, p_f, x_b, p_b, np.empty((n, n)), np.empty((n, 1)),
                                   np.empty((n, n)), x_c, p_c)
    np.testing.assert_allclose(x_c, x_s, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(p_c, p_s, rtol=1e-10, atol=1e-12)


def test_spool_round_trip():
    rng = np.random.default_rng(1)
    spool = StateSpool(27)
    mats = []
    for _ in range(5):
        a = rng.normal(size=(27, 27))
        mats.append((rng.normal(size=27), a @ a.T))
        spool.append(*mats[-1])
    for i in (4, 0, 2):
        x, p = spool.read(i)
        np.testing.assert_array_equal(x, mats[i][0])
        np.testing.assert_array_equal(p, mats[i][1])
    assert spool.bytes_per_epoch == 8 * (27 + 27 * 28 // 2)
    spool.close()


def test_output_epochs_grid():
    t = np.arange(0, 1.0, 0.01)
    imu = np.arange(t.size)
    out = output_epochs(t, imu, 10.0)
    assert out.size == 11 and out[0] == 0 and out[-1] == 99
    np.testing.assert_array_equal(np.diff(out[:-1]), 10)


def run_case(seed, duration_s=30.01):
    sim = simulate_model_matched(seed=seed, n_imu=21, duration_s=duration_s)
    ep, meas = model_matched_inputs(sim)
    p0 = model_matched_p0_sd(21)
    rng = np.random.default_rng(1000 + seed)
    x0 = sim["truth"][0] + rng.normal(0.0, 1.0, 21) * p0
    cfg = GmikfConfig(n_imu=21, q_sd=sim["q_sd"], imu_sd=sim["imu_sd"], lever_arm=sim["lever"],
                      p0_sd=p0, outlier_alpha=0.0)
    rec, sm = run_two_filter(ep, meas, x0, cfg, FRAME, rate_hz=10.0)
    return sim, ep, rec, sm


@pytest.mark.parametrize("runs", [8])
def test_smoothed_nees_in_chi2_band_and_sigma_below_forward(runs):
    nees = {"position": [], "velocity": [], "attitude": []}
    for seed in range(runs):
        sim, ep, rec, sm = run_case(seed)
        assert np.all(sm.sd <= rec.sd[sm.idx] * (1 + 1e-9) + 1e-15)
        err = sm.x - sim["truth"][ep.imu[sm.idx]]
        err[:, 9:12] = (err[:, 9:12] + np.pi) % (2 * np.pi) - np.pi
        rows = np.searchsorted(sm.t, (10.0, 20.0))   # 10 s apart: nearly independent
        for b, (name, sl) in enumerate([("position", slice(0, 3)), ("velocity", slice(3, 6)),
                                        ("attitude", slice(9, 12))]):
            e, c = err[rows, sl], sm.cov_blocks[rows, b]
            nees[name].append(np.einsum("ki,ki->k", e, np.linalg.solve(c, e[..., None])[..., 0]))
    for name, vals in nees.items():
        vals = np.concatenate(vals)
        n = vals.size
        lo, hi = stats.chi2.ppf([0.005, 0.995], 3 * n) / n
        assert lo <= vals.mean() <= hi, (name, vals.mean(), lo, hi)


def test_backward_inputs_phantoms_carry_no_measurement():
    from gmis.gmikf import EpochInputs
    from gmis.smoother import _backward_inputs

    e = 12
    t = np.arange(e) * 0.01
    ones = np.ones(e, dtype=np.bool_)
    inp = EpochInputs(t, np.arange(e), np.arange(e), np.arange(e), np.arange(e),
                      np.zeros((e, 6)), np.ones(6), np.zeros((e, 3)), np.ones((e, 3)),
                      np.zeros((e, 3)), np.ones((e, 3)), np.zeros(e), np.ones(e),
                      np.zeros(e, dtype=np.bool_), ones.copy(), ones.copy())
    still = np.arange(e) % 2 == 0
    out = np.array([0, 5, 11])
    seg, phantoms = _backward_inputs(inp, still, out, 1, 2, 11)   # epochs 11 … 5
    src = np.array([11, 11, 10, 9, 8, 7, 6, 5, 5])
    np.testing.assert_array_equal(seg.t, t[src])
    np.testing.assert_array_equal(phantoms, [0, 7])
    for a in (seg.imu_idx, seg.pos_idx, seg.vel_idx, seg.hdg_idx):
        np.testing.assert_array_equal(a[phantoms], -1)
        np.testing.assert_array_equal(np.delete(a, phantoms), np.delete(src, phantoms))
    assert not seg.nhc_on[phantoms].any() and not seg.zupt_on[phantoms].any()
    assert np.delete(seg.zupt_on, phantoms).all()
    np.testing.assert_array_equal(seg.still, still[np.minimum(src + 1, e - 1)])


def test_backward_lockout_streak_carries_across_blocks(monkeypatch):
    """The backward filter's lock-out recovery counts consecutive rejected GNSS epochs across
    its compiled blocks (gmis.lockout_recovery, as the forward filter across its chunks):
    a run of position blunders that straddles block boundaries gives the same smoothed
    solution with blocks of 5 output epochs as with one block for the whole run."""
    from gmis import smoother

    sim = simulate_model_matched(seed=3, n_imu=21, duration_s=20.01)
    sim["pos"][50:54, 0] += 3.0              # 0.8 s of fixes 3 m east (σ 2 cm): rejected
    ep, meas = model_matched_inputs(sim)
    p0 = model_matched_p0_sd(21)
    cfg = GmikfConfig(n_imu=21, q_sd=sim["q_sd"], imu_sd=sim["imu_sd"], lever_arm=sim["lever"],
                      p0_sd=p0)
    x0 = sim["truth"][0]
    results = []
    for block in (10_000, 5):
        monkeypatch.setattr(smoother, "BLOCK_OUTPUT_EPOCHS", block)
        results.append(run_two_filter(ep, meas, x0, cfg, FRAME, rate_hz=10.0)[1])
    one, many = results
    assert np.abs(one.x_backward[:, 0]).max() > 0   # the run did something
    np.testing.assert_allclose(many.x_backward, one.x_backward, rtol=0, atol=1e-9)
    np.testing.assert_allclose(many.x, one.x, rtol=0, atol=1e-9)
