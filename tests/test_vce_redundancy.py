"""VCE residuals and redundancy: formulas vs brute-force least squares of 001 eq. 2.7.13,
the identity r_z + r_w + r_x = m, and the numba loop's records vs the formulas."""

import numpy as np
import pytest

from gmis.epochs import merge_streams
from gmis.gmikf import SLOT_NAMES
from gmis.run_filter import GmikfConfig, Measurements, run_gmikf
from tests.model_matched_sim import (
    FRAME,
    model_matched_inputs,
    model_matched_p0_sd,
    simulate_model_matched,
)
from vce.kalman_ls import (
    block_redundancy,
    brute_force_helmert_matrix,
    brute_force_least_squares,
    helmert_matrix_elementary,
    kalman_residuals_and_redundancy,
)


def random_spd(rng, k, scale=1.0, correlated=True):
    a = rng.normal(size=(k, k))
    m = a @ a.T + k * np.eye(k) if correlated else np.diag(rng.uniform(0.5, 2, k))
    return scale * m / np.trace(m) * k


def random_update(rng, n_stop, draw_r):
    """A random update of the three-group LS problem: sizes n ∈ [2, n_stop), nw ∈ [1, 5),
    m ∈ [1, 6): (Σ_x (SPD), Λ, diagonal Q, R = draw_r(rng, m), H)."""
    n, nw, m = rng.integers(2, n_stop), rng.integers(1, 5), rng.integers(1, 6)
    sigma_x = random_spd(rng, n, 2.0)
    lam = rng.normal(size=(n, nw))
    q = np.diag(rng.uniform(0.1, 2.0, nw))
    r = draw_r(rng, m)
    h = rng.normal(size=(m, n))
    return sigma_x, lam, q, r, h


@pytest.mark.parametrize("correlated_r", [False, True])
def test_formulas_equal_brute_force_least_squares(correlated_r):
    rng = np.random.default_rng(11)
    for _ in range(50):
        phi_p_phi, lam, q, r, h = random_update(
            rng, 8, lambda g, k: random_spd(g, k, 0.5, correlated=correlated_r))
        m, n = h.shape
        x_pred = rng.normal(size=n)
        z = h @ x_pred + rng.normal(size=m) * 3
        d = z - h @ x_pred
        f = kalman_residuals_and_redundancy(d, h, phi_p_phi, lam, q, r)
        b = brute_force_least_squares(x_pred, z, h, phi_p_phi, lam, q, r)
        for key in ("v_z", "v_w", "v_x", "r_w", "R_z"):
            np.testing.assert_allclose(f[key], b[key], rtol=0, atol=1e-9, err_msg=key)
        assert abs(f["r_x"] - b["r_x"]) < 1e-9
        assert abs(f["r_z"].sum() + f["r_w"].sum() + f["r_x"] - m) < 1e-9
        # correlated group: block trace equals the LS group redundancy
        groups = [np.arange(m)]
        assert abs(block_redundancy(f["R_z"], groups)[0] - np.trace(b["R_z"])) < 1e-9


def test_helmert_matrix_scalar_form_equals_brute_force():
    rng = np.random.default_rng(5)
    for _ in range(20):
        sx, lam, q, r, h = random_update(rng, 7, lambda g, k: np.diag(g.uniform(0.1, 2.0, k)))
        m = h.shape[0]
        d = rng.normal(size=m)
        s, qv, rr = helmert_matrix_elementary(d, h, sx, lam, q, r)
        np.testing.assert_allclose(s, brute_force_helmert_matrix(h, sx, lam, q, r),
                                   rtol=1e-9, atol=1e-12)
        f = kalman_residuals_and_redundancy(d, h, sx, lam, q, r)
        np.testing.assert_allclose(qv[:m], f["v_z"] ** 2 / np.diag(r), rtol=1e-9)
        np.testing.assert_allclose(qv[m:], f["v_w"] ** 2 / np.diag(q), rtol=1e-9)
        np.testing.assert_allclose(rr, np.r_[f["r_z"], f["r_w"]], rtol=1e-9)


def test_loop_records_match_formulas_and_identity_holds_every_epoch():
    sim = simulate_model_matched(seed=4, n_imu=27, duration_s=3.0)
    ep, meas = model_matched_inputs(sim)
    p0 = model_matched_p0_sd(27)
    q_sd = sim["q_sd"]
    cfg = GmikfConfig(n_imu=27, q_sd=q_sd, imu_sd=sim["imu_sd"], lever_arm=sim["lever"],
                      p0_sd=p0, outlier_alpha=0.0, vce_mode=2, vce_noise_axes=18)
    rec = run_gmikf(ep, meas, sim["truth"][0], cfg, FRAME)
    total = np.nansum(rec.rz, axis=1) + np.nansum(rec.rw, axis=1) + rec.rx
    assert np.all(np.abs(total[1:] - rec.nobs[1:]) < 1e-9)
    assert set(np.unique(rec.nobs[1:])) == {6, 13}

    # recompute epoch 1 (IMU only) densely from the loop's epoch-0 output
    from gmis.measurement_models import imu_model_and_jacobian_into
    from gmis.system_model import propagate_state, transition_jacobians
    x_prev = rec.x[0]
    p_prev = _updated_p0(sim, p0)
    np.testing.assert_allclose(np.sqrt(np.diag(p_prev)), rec.sd[0], rtol=1e-9)
    dt = sim["t"][1] - sim["t"][0]
    phi, lam = transition_jacobians(x_prev, dt)
    x_pred = propagate_state(x_prev, np.zeros(18), dt, 27)
    h = np.zeros((6, 27))
    hx = np.zeros(6)
    imu_model_and_jacobian_into(x_pred, 27, FRAME, hx, 0, h, 0)
    d = sim["imu"][1] - hx
    f = kalman_residuals_and_redundancy(d, h, phi @ p_prev @ phi.T, lam,
                                        np.diag(q_sd ** 2), np.diag(sim["imu_sd"] ** 2))
    np.testing.assert_allclose(rec.innov[1, :6], d, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.vz[1, :6], f["v_z"], rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(rec.rz[1, :6], f["r_z"], rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(rec.vw[1], f["v_w"], rtol=1e-7, atol=1e-16)
    np.testing.assert_allclose(rec.rw[1], f["r_w"], rtol=1e-7, atol=1e-16)
    assert abs(rec.rx[1] - f["r_x"]) < 1e-8
    # the loop's accumulated Helmert matrix over epochs 0-1 (epoch 0 has no prediction,
    # so only epoch 1 contributes) equals the dense formula for epoch 1
    rec2 = run_gmikf(merge_streams(sim["t"][:2]), Measurements(imu_z=sim["imu"][:2]),
                     sim["truth"][0], cfg, FRAME)
    x0_upd = rec2.x[0]
    p_upd = _imu_only_updated_p0(sim, p0)
    phi, lam = transition_jacobians(x0_upd, dt)
    x_pred = propagate_state(x0_upd, np.zeros(18), dt, 27)
    imu_model_and_jacobian_into(x_pred, 27, FRAME, hx, 0, h, 0)
    s_ref, _, _ = helmert_matrix_elementary(sim["imu"][1] - hx, h, phi @ p_upd @ phi.T, lam,
                                            np.diag(q_sd ** 2), np.diag(sim["imu_sd"] ** 2))
    from gmis.gmikf import N_SLOTS
    rows = list(range(6)) + list(range(N_SLOTS, N_SLOTS + 18))
    loop_s = rec2.helmert_s[np.ix_(rows, rows)]
    np.testing.assert_allclose(loop_s, s_ref, rtol=1e-7, atol=1e-20)


def _imu_only_updated_p0(sim, p0):
    from gmis.measurement_models import imu_model_and_jacobian_into
    x = sim["truth"][0]
    h = np.zeros((6, 27))
    imu_model_and_jacobian_into(x, 27, FRAME, np.zeros(6), 0, h, 0)
    p = np.diag(p0 ** 2)
    s = h @ p @ h.T + np.diag(sim["imu_sd"] ** 2)
    return p - p @ h.T @ np.linalg.solve(s, h @ p)


def _updated_p0(sim, p0):
    """P after the epoch-0 update (IMU + GNSS at t=0), computed densely."""
    from gmis.measurement_models import (
        gnss_position_model_and_jacobian_into,
        gnss_velocity_model_and_jacobian_into,
        heading_model_and_jacobian_into,
        imu_model_and_jacobian_into,
    )
    x = sim["truth"][0]
    h = np.zeros((13, 27))
    hx = np.zeros(13)
    imu_model_and_jacobian_into(x, 27, FRAME, hx, 0, h, 0)
    gnss_position_model_and_jacobian_into(x, sim["lever"], hx, 6, h, 6)
    gnss_velocity_model_and_jacobian_into(x, sim["lever"], hx, 9, h, 9)
    heading_model_and_jacobian_into(x, hx, 12, h, 12)
    r = np.diag(np.r_[sim["imu_sd"] ** 2, [sim["pos_sd"] ** 2] * 3, [sim["vel_sd"] ** 2] * 3,
                      sim["hdg_sd"] ** 2])
    p = np.diag(p0 ** 2)
    s = h @ p @ h.T + r
    k = p @ h.T @ np.linalg.inv(s)
    return p - k @ h @ p


def test_slot_names_cover_all_sensors():
    from gmis.gmikf import GROUP_SIZE, GROUP_START, N_SLOTS
    assert len(SLOT_NAMES) == N_SLOTS == GROUP_START[-1] + GROUP_SIZE[-1]
    assert SLOT_NAMES[-2:] == ("nhc_lateral", "nhc_vertical")


def test_regional_f_test_detects_a_variance_change():
    from vce.estimate import regional_f_test
    rng = np.random.default_rng(8)
    r = np.full(4000, 0.8)
    same = (rng.normal(size=4000) ** 2) * 0.8
    f, crit, ok = regional_f_test(same, r)
    assert ok and 1.0 <= f < crit
    changed = same.copy()
    changed[2000:] *= 1.3                       # second half 30 % noisier
    f, crit, ok = regional_f_test(changed, r)
    assert not ok and f > crit
