"""CRLB recursions (gmis.crlb): analytic free-inertial growth, equality with the covariance
the real filters carry on noise-free data along the same truth, and mode ordering."""

import math
from dataclasses import replace

import numpy as np
import pytest

from gmis.crlb import (
    DEG,
    aiding_schedule,
    crlb_trajectory,
    errins_crlb,
    gmikf_crlb,
    grade_noise,
    run_crlb,
    table_4_2_p0,
)
from gmis.earth import gravity_nav_into
from gmis.epochs import merge_streams
from gmis.errins import ErrInsConfig, nav_state, run_errins
from gmis.imu_model import imu_measurement
from gmis.run_filter import GmikfConfig, Measurements, run_gmikf
from gmis.simulate.imu_grades import IMU_GRADES

RATE = 100.0


@pytest.fixture(scope="module")
def truth():
    tr = crlb_trajectory(duration_s=180.0, static_s=5.0, rate_hz=RATE)
    n = int(35 * RATE) + 1                      # 5 s static + 30 s of manoeuvres
    cut = {k: (v[:n] if isinstance(v, np.ndarray) and v.shape[:1] == tr.t.shape else v)
           for k, v in tr.__dict__.items()}
    return replace(tr, **cut)


def test_trajectory_shape():
    tr = crlb_trajectory()
    assert tr.t[-1] == pytest.approx(180.0)
    assert tr.static[:int(19 * RATE)].all() and not tr.static[int(25 * RATE):].any()
    assert np.abs(tr.r[:, 2]).max() < 1e-6              # constant height (within curvature)
    assert np.abs(np.degrees(tr.euler[:, 1])).max() > 4  # non-zero roll stretch
    assert np.ptp(np.unwrap(tr.euler[:, 2])) > math.pi / 2


def test_errins_free_inertial_bound_matches_analytic():
    """Static, level, no aiding, white noise only (HG1700 figures, biases known): per
    horizontal axis σ² = σ_a² δt t³/3 + g² σ_g² δt t⁵/20 (double integral of accelerometer
    noise and of tilt-induced g·φ)."""
    n = int(120 * RATE) + 1
    t = np.arange(n) / RATE
    zero = np.zeros(3)
    from gmis.earth import make_nav_frame
    frame = make_nav_frame(math.radians(45.0), 0.3, 100.0)
    euler = np.radians([0.0, 0.0, 40.0])
    imu = np.tile(imu_measurement(zero, zero, zero, euler, zero, zero, zero, zero, zero, frame),
                  (n, 1))
    nz = grade_noise("HG1700", RATE)
    dt = 1.0 / RATE
    p0 = np.r_[[1e-12] * 15]
    none = np.zeros(n, bool)
    sd = errins_crlb(t, np.zeros((n, 3)), np.zeros((n, 3)), np.tile(euler, (n, 1)), imu, none,
                     none, none, p0, np.full(3, nz.gyro_wn ** 2 * dt),
                     np.full(3, nz.accel_wn ** 2 * dt), zero, zero, 1.0, 1.0, 1.0, frame)
    g, dg = np.zeros(3), np.zeros((3, 3))
    gravity_nav_into(frame, zero, g, dg)
    gm = np.linalg.norm(g)
    for tc in (30.0, 60.0, 120.0):
        k = int(tc * RATE)
        analytic = math.sqrt(nz.accel_wn ** 2 * dt * tc ** 3 / 3
                             + gm ** 2 * nz.gyro_wn ** 2 * dt * tc ** 5 / 20)
        assert sd[k, 0] == pytest.approx(analytic, rel=0.03)
        assert sd[k, 1] == pytest.approx(analytic, rel=0.03)
    assert IMU_GRADES["HG1700"]["gyro_arw_deg_sqrt_h"] == 0.088


def _aiding(tr):
    aid, _ = aiding_schedule(tr, "loose")
    rows = np.nonzero(aid)[0]
    return rows


def test_gmikf_bound_equals_filter_covariance_on_noise_free_data(truth):
    """run_gmikf on error-free IMU/position/heading from x0 = truth carries the same P as the
    CRLB recursion (estimate stays on the truth up to the model's discretisation)."""
    tr = truth
    nz = grade_noise("IMU440", RATE)
    _, p0 = table_4_2_p0(nz)
    p0 = np.r_[[2.0] * 3, [0.05] * 3, [0.05] * 3, [0.5 * DEG] * 3, [0.1 * DEG] * 3,
               [nz.gyro_bias0 * 100] * 3, [nz.accel_bias0 * 100] * 3]
    q_sd = np.r_[[72.0] * 3, [50.0 * DEG] * 3, [0.0] * 6]
    imu_sd = np.r_[[nz.gyro_wn] * 3, [nz.accel_wn] * 3]
    rows = _aiding(tr)
    aid = np.zeros(tr.t.size, bool)
    aid[rows] = True
    sd_c = gmikf_crlb(tr.t, tr.r, tr.v_b, tr.a_b, tr.euler, tr.omega_b, tr.static, aid, aid,
                      p0, q_sd, imu_sd ** 2, 1.0, (0.1 * DEG) ** 2, False, tr.frame)
    meas = Measurements(imu_z=tr.imu, pos_enu=tr.r[rows], pos_sd=np.ones((rows.size, 3)),
                        heading=np.mod(tr.euler[rows, 2], 2 * math.pi),
                        heading_sd=np.full(rows.size, 0.1 * DEG))
    epochs = merge_streams(tr.t, tr.t[rows], None, tr.t[rows])
    x0 = np.zeros(21)
    x0[0:3], x0[3:6], x0[6:9] = tr.r[0], tr.v_b[0], tr.a_b[0]
    x0[9:12], x0[12:15] = tr.euler[0], tr.omega_b[0]
    cfg = GmikfConfig(n_imu=21, q_sd=np.r_[q_sd[:6], [1e-30] * 6], imu_sd=imu_sd,
                      lever_arm=np.zeros(3), p0_sd=p0, outlier_alpha=0.0)
    rec = run_gmikf(epochs, meas, x0, cfg, tr.frame)
    for k in (int(4 * RATE), int(20 * RATE), tr.t.size - 1):
        np.testing.assert_allclose(rec.sd[k], sd_c[k], rtol=2e-3)


def test_errins_bound_equals_filter_covariance_on_noise_free_data(truth):
    tr = truth
    nz = grade_noise("IMU440", RATE)
    p0 = np.r_[[2.0] * 3, [0.05] * 3, [0.5 * DEG] * 3, [nz.gyro_bias0 * 100] * 3,
               [nz.accel_bias0 * 100] * 3]
    rows = _aiding(tr)
    aid = np.zeros(tr.t.size, bool)
    aid[rows] = True
    dt = 1.0 / RATE
    qg = np.full(3, nz.gyro_wn ** 2 * dt)
    qa = np.full(3, nz.accel_wn ** 2 * dt)
    zero = np.zeros(3)
    sd_c = errins_crlb(tr.t, tr.r, tr.v_n, tr.euler, tr.imu, aid, aid, np.zeros_like(aid), p0,
                       qg, qa, zero, zero, 1.0, (0.1 * DEG) ** 2, 1.0, tr.frame)
    meas = Measurements(imu_z=tr.imu, pos_enu=tr.r[rows], pos_sd=np.ones((rows.size, 3)),
                        heading=np.mod(tr.euler[rows, 2], 2 * math.pi),
                        heading_sd=np.full(rows.size, 0.1 * DEG))
    epochs = merge_streams(tr.t, tr.t[rows], None, tr.t[rows])
    cfg = ErrInsConfig(imu_sd=[nz.gyro_wn] * 3 + [nz.accel_wn] * 3, bias_drift_sd=np.zeros(6),
                       imu_rate_hz=RATE, p0_sd=p0, lever_arm=zero, outlier_alpha=0.0)
    rec = run_errins(epochs, meas, nav_state(tr.r[0], tr.v_n[0], tr.euler[0]), cfg, tr.frame)
    for k in (int(4 * RATE), int(20 * RATE), tr.t.size - 1):
        np.testing.assert_allclose(rec.sd[k], sd_c[k], rtol=2e-3)


def test_mode_and_zupt_ordering(truth):
    """Aiding only lowers the bound; ZUPTs while static only lower the ErrINSEKF bound;
    a worse IMU has a larger free-inertial bound."""
    free = run_crlb(truth, "HG1700", "free")["final"]
    loose = run_crlb(truth, "HG1700", "loose")["final"]
    zupt = run_crlb(truth, "HG1700", "free", errins_zupt_sd=0.001)["final"]
    consumer = run_crlb(truth, "BP3010", "free")["final"]
    for f in ("errins", "gmikf"):
        assert loose[f]["horizontal_m"] < free[f]["horizontal_m"]
        assert consumer[f]["horizontal_m"] > free[f]["horizontal_m"]
    assert zupt["errins"]["horizontal_m"] < free["errins"]["horizontal_m"]
