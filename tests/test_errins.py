"""ErrINSEKF (gmis.errins): gravity helper, H and Φ against finite differences, mechanization
on an error-free IMU, NEES consistency over Monte Carlo runs, and free-inertial drift of a
tactical IMU against the analytic growth."""

import copy
import math

import numpy as np
import pytest
from scipy import stats

from gmis.earth import gravity_nav_into, make_nav_frame
from gmis.epochs import merge_streams
from gmis.errins import (
    ErrInsConfig,
    apply_correction,
    attitude_error,
    error_state_transition,
    heading_row_into,
    mechanize,
    nav_dcm,
    nav_state,
    position_rows_into,
    run_errins,
    velocity_rows_into,
)
from gmis.frames import dcm_body_to_nav
from gmis.gravity import gravity_nav_into as gravity_and_gradient_into
from gmis.imu_model import imu_measurement
from gmis.run_filter import Measurements
from gmis.simulate import load_scenario, scenario_path, validate_scenario
from gmis.simulate.imu_grades import IMU_GRADES
from gmis.simulate.sensors import ideal_imu_outputs
from gmis.simulate.trajectory import simulate_trajectory

FRAME = make_nav_frame(math.radians(43.77), math.radians(-79.50), 180.0)
DEG = math.pi / 180.0
HG1700 = IMU_GRADES["HG1700"]
ARW = HG1700["gyro_arw_deg_sqrt_h"] * DEG / 60.0            # rad/√s
VRW = HG1700["accel_vrw_m_s_sqrt_h"] / 60.0                 # m/s/√s
BG = HG1700["gyro_bias_instability_deg_h"] * DEG / 3600.0   # rad/s
BA = HG1700["accel_bias_instability_mg"] * 9.80665e-3       # m/s²
RATE = 100.0


def _random_nav(rng):
    return nav_state(rng.normal(0, 200, 3), rng.normal(0, 8, 3),
                     np.radians([rng.uniform(-20, 20), rng.uniform(-20, 20),
                                 rng.uniform(0, 360)]),
                     rng.normal(0, 1e-3, 3), rng.normal(0, 0.05, 3))


def test_gravity_helper_matches_earth_model():
    rng = np.random.default_rng(3)
    for _ in range(5):
        r = rng.normal(0, 5000, 3)
        g1, dg1, g2, dg2 = np.zeros(3), np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3))
        gravity_and_gradient_into(FRAME, r, g1, dg1)
        gravity_nav_into(FRAME, r, g2, dg2)
        np.testing.assert_allclose(g1, g2, rtol=0, atol=1e-12)
        np.testing.assert_allclose(dg1, dg2, rtol=0, atol=1e-15)


def _measurements(nav, w_imu, lever):
    h = np.zeros(7)
    jac = np.zeros((7, 15))
    position_rows_into(nav, lever, h, jac, 0)
    velocity_rows_into(nav, w_imu - nav[15:18], lever, FRAME, h, jac, 3)
    heading_row_into(nav, h, jac, 6)
    return h, jac


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_measurement_jacobian_matches_finite_differences_of_corrected_state(seed):
    """H = ∂h(x̂ ⊖ δx)/∂δx at δx = 0 (position, velocity with lever arm, heading)."""
    rng = np.random.default_rng(seed)
    nav = _random_nav(rng)
    lever = rng.normal(0, 1.0, 3)
    w_imu = rng.normal(0, 0.3, 3)
    _, jac = _measurements(nav, w_imu, lever)
    fd = np.zeros_like(jac)
    for j in range(15):
        step = np.zeros(15)
        step[j] = 1e-6
        hp, _ = _measurements(apply_correction(nav, step), w_imu, lever)
        hm, _ = _measurements(apply_correction(nav, -step), w_imu, lever)
        d = hp - hm
        d[6] = (d[6] + math.pi) % (2 * math.pi) - math.pi
        fd[:, j] = d / 2e-6
    np.testing.assert_allclose(jac, fd, rtol=0, atol=1e-7)
    assert np.abs(jac[3:6, 9:12]).max() > 0.1       # lever-arm rows really exercised


# finite-difference step per error state (δr m, δv m/s, ψ rad, b_ω rad/s, b_a m/s²)
FD_STEP = np.r_[[1.0] * 3, [0.1] * 3, [1e-3] * 3, [1e-5] * 3, [1e-3] * 3] * 1e-3


def _transition_product(truth, w_true, f_true, dt, steps, **kw):
    """Φ(steps)···Φ(1) of the error-state transition along the error-free mechanization."""
    phi_total = np.eye(15)
    x = truth.copy()
    for _ in range(steps):
        _, phi = error_state_transition(x, f_true, dt, FRAME, **kw)
        phi_total = phi @ phi_total
        x = mechanize(x, w_true, f_true, dt, FRAME)
    return phi_total


def _error(est, tru):
    d = np.zeros(15)
    d[0:6] = est[0:6] - tru[0:6]
    d[6:9] = attitude_error(nav_dcm(est), nav_dcm(tru))
    d[9:15] = est[15:21] - tru[15:21]
    return d


@pytest.mark.parametrize("steps", [1, 100])
def test_transition_matrix_matches_finite_differences_of_mechanization(steps):
    """Product of Φ over `steps` 100-Hz steps vs central differences of the error that
    the discrete mechanization propagates (estimate = truth ⊕ δx, same raw IMU)."""
    rng = np.random.default_rng(7)
    truth = _random_nav(rng)
    w_true = np.array([0.05, -0.02, 0.3])
    f_true = np.array([0.5, 1.2, 9.9])
    dt = 1.0 / RATE

    def propagate(nav):
        x = nav.copy()
        for _ in range(steps):
            # raw IMU = true + true bias; the estimate subtracts its own bias
            x = mechanize(x, w_true + truth[15:18] - x[15:18], f_true + truth[18:21] - x[18:21],
                          dt, FRAME)
        return x

    end = propagate(truth)
    phi_total = _transition_product(truth, w_true, f_true, dt, steps)
    scale = FD_STEP
    fd = np.zeros((15, 15))
    for j in range(15):
        e = np.zeros(15)
        e[j] = scale[j]
        fd[:, j] = (_error(propagate(apply_correction(truth, -e)), end)
                    - _error(propagate(apply_correction(truth, e)), end)) / (2 * scale[j])
    change = np.abs(phi_total - np.eye(15)).max(axis=0)
    rel = np.abs(fd - phi_total).max(axis=0) / np.maximum(change, 1e-30)
    assert rel.max() < 0.02, rel
    assert np.abs(fd - np.eye(15)).max() > 1e-3 * steps   # the test sees real coupling


def _scenario(duration_moving=50.0):
    sc = copy.deepcopy(load_scenario(scenario_path("tactical")))
    sc["scenario"]["imu_rate_hz"] = RATE
    sc["segment"] = [
        {"type": "static", "duration_s": 5.0},
        {"type": "accelerate", "speed_m_s": 12.0, "accel_m_s2": 2.0},
        {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 15.0, "bank_deg": 2.0},
        {"type": "cruise", "duration_s": 10.0, "roll_deg": 3.0},
        {"type": "turn", "angle_deg": -120.0, "rate_deg_s": 12.0},
        {"type": "climb", "pitch_deg": 3.0, "duration_s": 8.0},
        {"type": "cruise", "duration_s": duration_moving},
    ]
    sc = validate_scenario(sc, "test")
    traj, frame = simulate_trajectory(sc, np.random.default_rng(0), "test")
    return traj, frame


@pytest.fixture(scope="module")
def trajectory():
    traj, frame = _scenario()
    n = int(60.0 * RATE) + 1
    z = np.zeros(3)
    ideal = ideal_imu_outputs(traj.r_enu[:n], traj.v_b[:n], traj.a_b[:n], traj.euler[:n],
                              traj.omega_b[:n], np.zeros((n, 3)), np.zeros((n, 3)), z, z, frame)
    return {"t": traj.t_s[:n], "r": traj.r_enu[:n], "v": traj.v_enu[:n],
            "euler": traj.euler[:n], "ideal": ideal, "frame": frame}


def _truth_nav(tr, k, bg=(0, 0, 0), ba=(0, 0, 0)):
    return nav_state(tr["r"][k], tr["v"][k], tr["euler"][k], bg, ba)


def test_mechanization_follows_error_free_imu(trajectory):
    """Pure mechanization of the ideal IMU over 60 s of turns, bank, climb: < 5 cm, < 2 mm/s,
    < 2e-5 rad (discretisation error only)."""
    tr = trajectory
    nav = _truth_nav(tr, 0)
    dt = 1.0 / RATE
    for k in range(1, tr["t"].size):
        m = 0.5 * (tr["ideal"][k - 1] + tr["ideal"][k])
        nav = mechanize(nav, m[:3], m[3:], dt, tr["frame"])
    end = _truth_nav(tr, tr["t"].size - 1)
    d = _error(nav, end)
    assert np.linalg.norm(d[0:3]) < 0.05
    assert np.linalg.norm(d[3:6]) < 2e-3
    assert np.linalg.norm(d[6:9]) < 2e-5


def _mc_run(tr, seed, aid=True, outage=(38.0, 52.0)):
    """One model-matched run: biases ~ P0 then random walk, white IMU noise, GNSS/heading
    at 5 Hz with lever arm, initial error ~ P0. Returns (records, truth biases)."""
    rng = np.random.default_rng(seed)
    n = tr["t"].size
    dt = 1.0 / RATE
    imu_sd = np.r_[np.full(3, ARW / math.sqrt(dt)), np.full(3, VRW / math.sqrt(dt))]
    drift_sd = np.r_[np.full(3, BG * math.sqrt(dt / 100.0)), np.full(3, BA * math.sqrt(dt / 100.0))]
    p0 = np.r_[[0.3] * 3, [0.05] * 3, np.radians([0.05, 0.05, 0.3]), [BG * 3] * 3, [BA * 3] * 3]
    bias0 = rng.normal(0, 1, 6) * p0[9:15]
    bias = bias0 + np.vstack([np.zeros(6), np.cumsum(rng.normal(0, 1, (n - 1, 6)) * drift_sd,
                                                     axis=0)])
    imu = tr["ideal"] + bias + rng.normal(0, 1, (n, 6)) * imu_sd
    lever = np.array([0.2, 0.8, 1.5])
    g_rows = np.arange(0, n, 20)
    if not aid:
        g_rows = g_rows[:0]
    tg = tr["t"][g_rows]
    keep = ~((tg >= outage[0]) & (tg <= outage[1]))
    g_rows = g_rows[keep]
    pos_sd = np.array([0.05, 0.05, 0.1])
    vel_sd = np.array([0.03, 0.03, 0.05])
    hdg_sd = math.radians(0.3)
    pos = np.empty((g_rows.size, 3))
    vel = np.empty((g_rows.size, 3))
    for i, k in enumerate(g_rows):
        c = dcm_body_to_nav(*tr["euler"][k])
        w_ib = tr["ideal"][k, :3]          # true ω_ib
        pos[i] = tr["r"][k] + c @ lever + rng.normal(0, 1, 3) * pos_sd
        vel[i] = (tr["v"][k] + c @ np.cross(w_ib, lever) - np.cross(tr["frame"][15:18], c @ lever)
                  + rng.normal(0, 1, 3) * vel_sd)
    hdg = np.mod(tr["euler"][g_rows, 2] + rng.normal(0, hdg_sd, g_rows.size), 2 * math.pi)
    meas = Measurements(imu_z=imu, pos_enu=pos, pos_sd=np.tile(pos_sd, (g_rows.size, 1)),
                        vel_enu=vel, vel_sd=np.tile(vel_sd, (g_rows.size, 1)), heading=hdg,
                        heading_sd=np.full(g_rows.size, hdg_sd))
    epochs = merge_streams(tr["t"], tg[keep], tg[keep], tg[keep])
    err0 = rng.normal(0, 1, 15) * p0
    err0[9:15] = 0.0
    nav0 = apply_correction(_truth_nav(tr, 0), -err0)    # estimate = truth ⊕ δx0
    nav0[15:21] = 0.0                                     # bias estimates start at zero
    cfg = ErrInsConfig(imu_sd=imu_sd, bias_drift_sd=drift_sd, imu_rate_hz=RATE, p0_sd=p0,
                       lever_arm=lever, outlier_alpha=0.0)
    return run_errins(epochs, meas, nav0, cfg, tr["frame"]), bias


def test_nees_consistency_monte_carlo(trajectory):
    """Position, velocity and attitude NEES averaged over 30 runs at 4 times (one at the
    end of a 14-s GNSS/heading outage) inside the χ²(3N)/N band; 12 checks share a
    family-wise two-sided 95 % level (Bonferroni: 0.05/12 per check), otherwise a consistent
    filter would fail one of them about every other time."""
    tr = trajectory
    runs = 30
    check_t = [10.0, 30.0, 51.9, 59.0]
    nees = {name: np.zeros((runs, len(check_t))) for name in ("pos", "vel", "att")}
    for s in range(runs):
        rec, _ = _mc_run(tr, 100 + s)
        for j, tc in enumerate(check_t):
            e = int(np.argmin(np.abs(rec.t - tc)))
            k = rec.imu_row[e]
            truth = _truth_nav(tr, k)
            est = truth.copy()
            est[0:6] = rec.nav[e, 0:6]
            est[6:15] = dcm_body_to_nav(*rec.nav[e, 6:9]).ravel()
            d = _error(est, truth)
            for b, name in enumerate(("pos", "vel", "att")):
                blk = rec.cov_blocks[e, b]
                v = d[3 * b:3 * b + 3]
                nees[name][s, j] = v @ np.linalg.solve(blk, v)
    alpha = 0.05 / (3 * len(check_t))
    lo = stats.chi2.ppf(alpha / 2, 3 * runs) / runs
    hi = stats.chi2.ppf(1 - alpha / 2, 3 * runs) / runs
    means = {k: v.mean(axis=0) for k, v in nees.items()}
    for name, m in means.items():
        assert np.all((m > lo) & (m < hi)), (name, m, lo, hi)
    print("NEES means", {k: np.round(v, 2).tolist() for k, v in means.items()},
          "band", round(lo, 2), round(hi, 2))


def test_free_inertial_drift_matches_analytic_growth(trajectory):
    """Static, level, free-inertial tactical IMU (HG1700: ARW, VRW, constant biases ~ N(0,
    BS²)), no aiding. Per horizontal axis, with g the gravity magnitude,
        σ²(t) = VRW² t³/3 + (b_a t²/2)² + g² ARW² t⁵/20 + (g b_ω t³/6)²
    (double integral of accelerometer noise/bias and of the tilt-induced g·φ; earth-rate
    and Schuler terms are < 1 % at 60 s). Monte Carlo RMS over 40 runs × 2 axes and the
    filter's own σ must both agree with it within 20 % at 20, 40, 60 s."""
    frame = FRAME
    n = int(60 * RATE) + 1
    dt = 1.0 / RATE
    t = np.arange(n) * dt
    euler = np.radians([0.0, 0.0, 30.0])
    zero = np.zeros(3)
    ideal = imu_measurement(zero, zero, zero, euler, zero, zero, zero, zero, zero, frame)
    gvec, dg = np.zeros(3), np.zeros((3, 3))
    gravity_nav_into(frame, zero, gvec, dg)
    g = float(np.linalg.norm(gvec))
    imu_sd = np.r_[np.full(3, ARW / math.sqrt(dt)), np.full(3, VRW / math.sqrt(dt))]
    p0 = np.r_[[1e-9] * 9, [BG] * 3, [BA] * 3]
    cfg = ErrInsConfig(imu_sd=imu_sd, bias_drift_sd=np.zeros(6), imu_rate_hz=RATE, p0_sd=p0,
                       lever_arm=zero, outlier_alpha=0.0)
    epochs = merge_streams(t)
    runs = 40
    times = [20.0, 40.0, 60.0]
    idx = [round(x * RATE) for x in times]
    errs = np.zeros((runs, len(times), 2))
    sd_filter = None
    for s in range(runs):
        rng = np.random.default_rng(500 + s)
        bias = np.r_[rng.normal(0, BG, 3), rng.normal(0, BA, 3)]
        imu = ideal + bias + rng.normal(0, 1, (n, 6)) * imu_sd
        rec = run_errins(epochs, Measurements(imu_z=imu), nav_state(zero, zero, euler), cfg,
                         frame)
        errs[s] = rec.nav[idx, 0:2]
        sd_filter = rec.sd[idx, 0:2]
    tt = np.array(times)
    analytic = np.sqrt(VRW ** 2 * tt ** 3 / 3 + (BA * tt ** 2 / 2) ** 2
                       + g ** 2 * ARW ** 2 * tt ** 5 / 20 + (g * BG * tt ** 3 / 6) ** 2)
    mc_rms = np.sqrt((errs ** 2).mean(axis=(0, 2)))
    assert np.all(np.abs(mc_rms / analytic - 1) < 0.2), (mc_rms, analytic)
    assert np.all(np.abs(sd_filter.mean(axis=1) / analytic - 1) < 0.2), (sd_filter, analytic)


@pytest.mark.parametrize("steps", [1, 100])
def test_gauss_markov_transition_matches_finite_differences(steps):
    """Per-axis Gauss-Markov biases (b' = e^{−Δt/τ} b, truth and estimate alike): Φ over
    `steps` steps against central differences of the propagated error; the bias block
    is e^{−kΔt/τ}."""
    rng = np.random.default_rng(8)
    truth = _random_nav(rng)
    tau = np.array([0.5, 3.0, math.inf, 2.0, math.inf, 0.8])
    w_true = np.array([0.05, -0.02, 0.3])
    f_true = np.array([0.5, 1.2, 9.9])
    dt = 1.0 / RATE
    decay = np.exp(-dt / tau)

    def propagate(nav, true_bias):
        x, b = nav.copy(), true_bias.copy()
        for _ in range(steps):
            x = mechanize(x, w_true + b[:3] - x[15:18], f_true + b[3:] - x[18:21], dt, FRAME)
            x[15:21] *= decay
            b = b * decay
        return x

    end = propagate(truth, truth[15:21])
    phi_total = _transition_product(truth, w_true, f_true, dt, steps, bias_tau_s=tau)
    scale = FD_STEP
    fd = np.zeros((15, 15))
    for j in range(15):
        e = np.zeros(15)
        e[j] = scale[j]
        fd[:, j] = (_error(propagate(apply_correction(truth, -e), truth[15:21]), end)
                    - _error(propagate(apply_correction(truth, e), truth[15:21]), end)) \
            / (2 * scale[j])
    change = np.abs(phi_total - np.eye(15)).max(axis=0)
    rel = np.abs(fd - phi_total).max(axis=0) / np.maximum(change, 1e-30)
    assert rel.max() < 0.02, rel
    assert np.allclose(np.diag(phi_total)[9:15], decay ** steps, rtol=1e-12)


def test_gauss_markov_bias_variance_settles_at_sigma2():
    """Free inertial, static: a Gauss-Markov bias of stationary σ (driving σ√(2δt/τ))
    keeps its filter variance at σ² from P0 = σ² (the random walk would grow)."""
    n = int(30 * RATE) + 1
    t = np.arange(n) / RATE
    tau, sigma = 5.0, 1e-3
    drift = np.full(6, sigma * math.sqrt(2.0 / RATE / tau))
    cfg = ErrInsConfig(imu_sd=np.full(6, 1e-6), bias_drift_sd=drift, imu_rate_hz=RATE,
                       p0_sd=np.r_[[1e-6] * 9, [sigma] * 6], lever_arm=np.zeros(3),
                       bias_tau_s=[tau] * 6, outlier_alpha=0.0)
    zero = np.zeros(3)
    euler = np.zeros(3)
    ideal = imu_measurement(zero, zero, zero, euler, zero, zero, zero, zero, zero, FRAME)
    rec = run_errins(merge_streams(t), Measurements(imu_z=np.tile(ideal, (n, 1))),
                     nav_state(zero, zero, euler), cfg, FRAME)
    assert np.allclose(rec.sd[-1, 9:15], sigma, rtol=2e-3)
    with pytest.raises(ValueError, match="bias_tau_s"):
        ErrInsConfig(imu_sd=np.ones(6), bias_drift_sd=np.ones(6), imu_rate_hz=RATE,
                     p0_sd=np.ones(15), lever_arm=zero, bias_tau_s=[1.0, -2.0])
