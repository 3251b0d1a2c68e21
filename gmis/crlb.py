"""Covariance (Cramér-Rao lower bound) analysis of the ErrINSEKF and the GMIKF along a
simulated TRUE trajectory (001 §4.2.2-4.2.3, eq. 4.2.3-4.2.5, Fig. 4-5..4-9, Tables 4-1..4-4).

For an EKF linearised about the true trajectory the covariance recursion
    P⁻ = Φ P Φᵀ + Q,   P = (P⁻⁻¹ + Hᵀ R⁻¹ H)⁻¹                                   (4.2.3)
is the CRLB (Taylor 1978). Only P is propagated — no data, no noise draws.

Stochastic model (001 eq. 4.2.4/4.2.5 and Tables 4-2..4-4), per IMU grade of Table 4-1
(gmis.simulate.imu_grades), δt = IMU interval, T = bias correlation time (100 s, 001
§5.3.2.2):
    σ_RW = RW/√δt (per-sample white noise),  σ_BS = BS √(δt/T)
    sensor white noise   σ_wn = √(σ_RW² + σ_BS²)     ErrINSEKF: process noise (gyro, accel)
                                                     GMIKF: IMU measurement noise
    biases: random constants (4.2.4) with initial σ = BS √(δt/T) (Table 4-2)
    initial σ: position 10 m, velocity 0.001 m/s, attitude 0.1°; GMIKF also a^b 1e-6 m/s²,
    ω 1e-6 °/s (Table 4-2 prints "10e-7")
    GMIKF process noise (Table 4-3): jerk 72 m/s³, angular acceleration 50 °/s² per step
    while moving, 0 while static (taken from the true trajectory, as in 001)
    aiding (Table 4-4): position 1 m per axis at 1 Hz, heading 0.1° at 1 Hz.

Modes: "loose" — aiding over the whole run; "free" — aiding only during the initial static
period (``aided_s``), free-inertial afterwards (the ErrINSEKF then only propagates, the GMIKF
only takes its IMU measurement updates).

The ErrINSEKF uses gmis.errins' F/Φ, Q_d and H; the GMIKF uses
gmis.system_model.transition_jacobians_into and gmis.measurement_models (IMU, position,
heading), i.e. exactly the matrices the two filters run with.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gmis.errins import (
    N_ERR,
    ROW_HEADING,
    error_state_transition_into,
    heading_row_into,
    position_rows_into,
    predict_covariance_into,
    process_noise_into,
)
from gmis.frames import dcm_body_to_nav_into
from gmis.gmikf import SLOT_HEADING, SLOT_POS, add_process_noise, propagate_covariance
from gmis.measurement_models import (
    gnss_position_model_and_jacobian_into,
    heading_model_and_jacobian_into,
    imu_model_and_jacobian_into,
)
from gmis.simulate import load_scenario, scenario_path, validate_scenario
from gmis.simulate.imu_grades import G0, GRADE_NAMES, IMU_GRADES
from gmis.simulate.sensors import ideal_imu_outputs
from gmis.simulate.trajectory import simulate_trajectory
from gmis.state import (
    I_ACC,
    I_ATT,
    I_DV,
    I_NAV_C,
    I_NAV_R,
    I_NAV_V,
    I_POS,
    I_RATE,
    I_VEL,
    N_DYNAMIC,
    N_KINEMATIC_NOISE,
)
from gmis.system_model import transition_jacobians_into

DEG = math.pi / 180.0
BIAS_CORRELATION_TIME_S = 100.0
N_GMIKF = 21


@dataclass
class TruthTrajectory:
    t: np.ndarray        # (N,) s
    r: np.ndarray        # (N,3) ENU m
    v_b: np.ndarray      # (N,3)
    v_n: np.ndarray      # (N,3)
    a_b: np.ndarray      # (N,3)
    euler: np.ndarray    # (N,3) pitch, roll, heading rad
    omega_b: np.ndarray  # (N,3) ω_nb^b rad/s
    imu: np.ndarray      # (N,6) error-free gyro rad/s, accel m/s²
    static: np.ndarray   # (N,) bool, vehicle at rest
    frame: np.ndarray


def crlb_trajectory(duration_s: float = 180.0, static_s: float = 20.0,
                    rate_hz: float = 100.0) -> TruthTrajectory:
    """001 Fig. 4-3/4-4-like truth: north-facing, level, at rest for static_s, then constant
    accelerations, constant-velocity runs, circular turns and a banked (non-zero roll)
    constant-velocity run at constant height, padded with a final cruise to duration_s."""
    sc = copy.deepcopy(load_scenario(scenario_path("default")))
    sc["scenario"]["imu_rate_hz"] = rate_hz
    sc["initial"]["heading_deg"] = 0.0
    moving = [
        {"type": "accelerate", "speed_m_s": 10.0, "accel_m_s2": 1.0},
        {"type": "cruise", "duration_s": 10.0},
        {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 9.0},
        {"type": "accelerate", "speed_m_s": 15.0, "accel_m_s2": 1.0},
        {"type": "cruise", "duration_s": 15.0, "roll_deg": 5.0},
        {"type": "turn", "angle_deg": -90.0, "rate_deg_s": 10.0, "bank_deg": 3.0},
        {"type": "accelerate", "speed_m_s": 8.0, "accel_m_s2": 1.0},
        {"type": "cruise", "duration_s": 10.0, "roll_deg": 0.0},
        {"type": "turn", "angle_deg": 180.0, "rate_deg_s": 12.0},
        {"type": "accelerate", "speed_m_s": 12.0, "accel_m_s2": 1.0},
        {"type": "turn", "angle_deg": -90.0, "rate_deg_s": 10.0},
    ]
    segs = ([{"type": "static", "duration_s": static_s}] if static_s > 0 else []) + moving

    def build(segments):
        s = copy.deepcopy(sc)
        s["segment"] = segments
        return simulate_trajectory(validate_scenario(s, "crlb"), np.random.default_rng(0),
                                   "crlb")

    traj, _ = build(segs)
    rest = duration_s - traj.t_s[-1]
    if rest < 1.0:
        raise ValueError(f"duration_s = {duration_s} is shorter than the manoeuvres "
                         f"({traj.t_s[-1]:.1f} s)")
    traj, frame = build(segs + [{"type": "cruise", "duration_s": rest}])
    n = round(duration_s * rate_hz) + 1
    z = np.zeros(3)
    imu = ideal_imu_outputs(traj.r_enu[:n], traj.v_b[:n], traj.a_b[:n], traj.euler[:n],
                            traj.omega_b[:n], np.zeros((n, 3)), np.zeros((n, 3)), z, z, frame)
    static = ((np.abs(traj.v_b[:n]).max(axis=1) < 1e-9)
              & (np.abs(traj.omega_b[:n]).max(axis=1) < 1e-12)
              & (np.abs(traj.a_b[:n]).max(axis=1) < 1e-9))
    return TruthTrajectory(traj.t_s[:n], traj.r_enu[:n], traj.v_b[:n], traj.v_enu[:n],
                           traj.a_b[:n], traj.euler[:n], traj.omega_b[:n], imu, static, frame)


@dataclass
class GradeNoise:
    """Table 4-2..4-4 figures of one grade (SI, per sample / per step at rate_hz)."""
    gyro_wn: float        # rad/s per sample √(σ_RW² + σ_BS²)
    accel_wn: float       # m/s² per sample
    gyro_bias0: float     # rad/s, BS √(δt/T)
    accel_bias0: float    # m/s²


def grade_noise(grade: str, rate_hz: float = 100.0,
                correlation_time_s: float = BIAS_CORRELATION_TIME_S) -> GradeNoise:
    g = IMU_GRADES[grade]
    dt = 1.0 / rate_hz
    rw_g = g["gyro_arw_deg_sqrt_h"] * DEG / 60.0 / math.sqrt(dt)
    rw_a = g["accel_vrw_m_s_sqrt_h"] / 60.0 / math.sqrt(dt)
    bs_g = g["gyro_bias_instability_deg_h"] * DEG / 3600.0 * math.sqrt(dt / correlation_time_s)
    bs_a = g["accel_bias_instability_mg"] * 1e-3 * G0 * math.sqrt(dt / correlation_time_s)
    return GradeNoise(math.hypot(rw_g, bs_g), math.hypot(rw_a, bs_a), bs_g, bs_a)


@njit(cache=True)
def _scalar_update(p, h_row, r_var, ph):
    n = p.shape[0]
    for i in range(n):
        s = 0.0
        for j in range(n):
            if h_row[j] != 0.0:
                s += p[i, j] * h_row[j]
        ph[i] = s
    s_var = r_var
    for j in range(n):
        s_var += h_row[j] * ph[j]
    for i in range(n):
        for j in range(i, n):
            p[i, j] -= ph[i] * ph[j] / s_var
            p[j, i] = p[i, j]


@njit(cache=True)
def errins_crlb(t, r, v_n, euler, imu, aid_pos, aid_hdg, zupt, p0_sd, q_gyro, q_accel,
                q_bg, q_ba, pos_var, hdg_var, zupt_var, frame):
    """ErrINSEKF covariance along the truth; returns √diag P (N, 15) after each epoch.
    F/Φ at the true state with the interval-mean specific force (as the filter uses).
    zupt[k]: zero-velocity update (δv rows, variance zupt_var) at epoch k."""
    n = t.size
    p = np.zeros((N_ERR, N_ERR))
    for i in range(N_ERR):
        p[i, i] = p0_sd[i] ** 2
    out = np.empty((n, N_ERR))
    nav = np.zeros(21)
    c = np.zeros((3, 3))
    f_mat = np.zeros((N_ERR, N_ERR))
    phi = np.zeros((N_ERR, N_ERR))
    qd = np.zeros((N_ERR, N_ERR))
    work = np.zeros((N_ERR, N_ERR))
    work2 = np.zeros((N_ERR, N_ERR))
    g = np.zeros(3)
    dg = np.zeros((3, 3))
    h = np.zeros(7)
    jac = np.zeros((7, N_ERR))
    ph = np.zeros(N_ERR)
    lever = np.zeros(3)
    for k in range(n):
        for i in range(3):
            nav[I_NAV_R + i] = r[k, i]
            nav[I_NAV_V + i] = v_n[k, i]
        dcm_body_to_nav_into(euler[k, 0], euler[k, 1], euler[k, 2], c)
        for i in range(3):
            for j in range(3):
                nav[I_NAV_C + 3 * i + j] = c[i, j]
        if k > 0:
            dt = t[k] - t[k - 1]
            fx = 0.5 * (imu[k - 1, 3] + imu[k, 3])
            fy = 0.5 * (imu[k - 1, 4] + imu[k, 4])
            fz = 0.5 * (imu[k - 1, 5] + imu[k, 5])
            error_state_transition_into(nav, fx, fy, fz, dt, frame, np.inf, np.inf, f_mat,
                                        phi, work, dg, g)
            process_noise_into(nav, dt, q_gyro, q_accel, q_bg, q_ba, phi, qd, work, work2)
            predict_covariance_into(p, phi, qd, work, work2)
        if aid_pos[k]:
            position_rows_into(nav, lever, h, jac, 0)
            for i in range(3):
                _scalar_update(p, jac[i], pos_var, ph)
        if aid_hdg[k]:
            heading_row_into(nav, h, jac, ROW_HEADING)
            _scalar_update(p, jac[ROW_HEADING], hdg_var, ph)
        if zupt[k]:
            for i in range(3):
                for j in range(N_ERR):
                    jac[0, j] = 0.0
                jac[0, I_DV + i] = -1.0
                _scalar_update(p, jac[0], zupt_var, ph)
        for i in range(N_ERR):
            out[k, i] = math.sqrt(max(p[i, i], 0.0))
    return out


@njit(cache=True)
def _truth_state_into(x, k, r, v_b, a_b, euler, omega_b):
    """The GMIKF state r^n, v^b, a^b, θ, ω^b of truth sample k (biases left as they are)."""
    for i in range(3):
        x[I_POS + i] = r[k, i]
        x[I_VEL + i] = v_b[k, i]
        x[I_ACC + i] = a_b[k, i]
        x[I_ATT + i] = euler[k, i]
        x[I_RATE + i] = omega_b[k, i]


@njit(cache=True)
def gmikf_crlb(t, r, v_b, a_b, euler, omega_b, static, aid_pos, aid_hdg, p0_sd, q_sd,
               imu_var, pos_var, hdg_var, zero_q_static, frame):
    """GMIKF (21 states) covariance along the truth: Φ P Φᵀ + Λ Q Λᵀ (eq. 5.1.2), then the
    IMU update (R = imu_var, (6,)) and the aiding updates; returns √diag P (N, 21)."""
    n = t.size
    ns = N_GMIKF
    p = np.zeros((ns, ns))
    for i in range(ns):
        p[i, i] = p0_sd[i] ** 2
    out = np.empty((n, ns))
    x = np.zeros(ns)
    phi_dyn = np.zeros((N_DYNAMIC, N_DYNAMIC))
    lam = np.zeros((N_DYNAMIC, N_KINEMATIC_NOISE))
    work = np.zeros((N_DYNAMIC, ns))
    q_var = np.zeros(q_sd.size)
    h6 = np.zeros(13)
    jac = np.zeros((13, ns))
    ph = np.zeros(ns)
    lever = np.zeros(3)
    xp = np.zeros(ns)
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            _truth_state_into(xp, k - 1, r, v_b, a_b, euler, omega_b)
            transition_jacobians_into(xp, dt, phi_dyn, lam)
            propagate_covariance(p, ns, phi_dyn, work)
            moving_scale = 0.0 if (zero_q_static and static[k - 1] and static[k]) else 1.0
            for m in range(q_var.size):
                q_var[m] = q_sd[m] * q_sd[m] * (moving_scale if m < N_KINEMATIC_NOISE else 1.0)
            add_process_noise(p, lam, q_var, ns)
        _truth_state_into(x, k, r, v_b, a_b, euler, omega_b)
        imu_model_and_jacobian_into(x, ns, frame, h6, 0, jac, 0)
        for i in range(6):
            _scalar_update(p, jac[i], imu_var[i], ph)
        if aid_pos[k]:
            gnss_position_model_and_jacobian_into(x, lever, h6, SLOT_POS, jac, SLOT_POS)
            for i in range(3):
                _scalar_update(p, jac[SLOT_POS + i], pos_var, ph)
        if aid_hdg[k]:
            heading_model_and_jacobian_into(x, h6, SLOT_HEADING, jac, SLOT_HEADING)
            _scalar_update(p, jac[SLOT_HEADING], hdg_var, ph)
        for i in range(ns):
            out[k, i] = math.sqrt(max(p[i, i], 0.0))
    return out


def aiding_schedule(tr: TruthTrajectory, mode: str, aid_rate_hz: float = 1.0,
                    aided_s: float | None = None):
    """Boolean (N,) arrays: epochs with position and heading aiding."""
    rate = 1.0 / (tr.t[1] - tr.t[0])
    step = round(rate / aid_rate_hz)
    aid = np.zeros(tr.t.size, bool)
    aid[::step] = True
    if mode == "free":
        if aided_s is None:
            moving = np.nonzero(~tr.static)[0]
            aided_s = tr.t[moving[0]] if moving.size else tr.t[-1]
        aid &= tr.t <= aided_s + 1e-9
    elif mode != "loose":
        raise ValueError(f"mode must be 'free' or 'loose', got {mode!r}")
    return aid, aid.copy()


def table_4_2_p0(noise: GradeNoise):
    """Initial 1σ (Table 4-2) for the ErrINSEKF (15) and the GMIKF (21)."""
    e = np.r_[[10.0] * 3, [0.001] * 3, [0.1 * DEG] * 3, [noise.gyro_bias0] * 3,
              [noise.accel_bias0] * 3]
    g = np.r_[[10.0] * 3, [0.001] * 3, [1e-6] * 3, [0.1 * DEG] * 3, [1e-6 * DEG] * 3,
              [noise.gyro_bias0] * 3, [noise.accel_bias0] * 3]
    return e, g


def run_crlb(tr: TruthTrajectory, grade: str, mode: str, pos_sd_m: float = 1.0,
             heading_sd_deg: float = 0.1, aid_rate_hz: float = 1.0,
             jerk_m_s3: float = 72.0, angacc_deg_s2: float = 50.0, zero_q_static=True,
             errins_zupt_sd: float | None = None):
    """√CRLB histories of both filters for one grade and mode: dict with 'errins' (N, 15),
    'gmikf' (N, 21) and the final horizontal/up position bounds (m).

    errins_zupt_sd (m/s): also give the ErrINSEKF a zero-velocity update at every static
    epoch — the information the GMIKF gets from its zero process noise while static
    (Table 4-3); None = the thesis setting (no ZUPT)."""
    rate = 1.0 / (tr.t[1] - tr.t[0])
    dt = 1.0 / rate
    nz = grade_noise(grade, rate)
    aid_pos, aid_hdg = aiding_schedule(tr, mode, aid_rate_hz)
    p0_e, p0_g = table_4_2_p0(nz)
    q_gyro = np.full(3, nz.gyro_wn ** 2 * dt)
    q_accel = np.full(3, nz.accel_wn ** 2 * dt)
    zero3 = np.zeros(3)
    zupt = tr.static if errins_zupt_sd is not None else np.zeros(tr.t.size, bool)
    zupt_var = (errins_zupt_sd or 1.0) ** 2
    sd_e = errins_crlb(tr.t, tr.r, tr.v_n, tr.euler, tr.imu, aid_pos, aid_hdg, zupt, p0_e,
                       q_gyro, q_accel, zero3, zero3, pos_sd_m ** 2, (heading_sd_deg * DEG) ** 2,
                       zupt_var, tr.frame)
    q_sd = np.r_[[jerk_m_s3] * 3, [angacc_deg_s2 * DEG] * 3, zero3, zero3]
    imu_var = np.r_[[nz.gyro_wn ** 2] * 3, [nz.accel_wn ** 2] * 3]
    sd_g = gmikf_crlb(tr.t, tr.r, tr.v_b, tr.a_b, tr.euler, tr.omega_b, tr.static, aid_pos,
                      aid_hdg, p0_g, q_sd, imu_var, pos_sd_m ** 2, (heading_sd_deg * DEG) ** 2,
                      zero_q_static, tr.frame)
    final = {name: {"horizontal_m": float(np.hypot(sd[-1, 0], sd[-1, 1])),
                    "up_m": float(sd[-1, 2])} for name, sd in (("errins", sd_e), ("gmikf", sd_g))}
    return {"errins": sd_e, "gmikf": sd_g, "final": final}


def crlb_table(grades=GRADE_NAMES, modes=("free", "loose"), duration_s: float = 180.0,
               static_s: float = 20.0, rate_hz: float = 100.0, zupt_sd: float = 0.001):
    """Final √CRLB position (horizontal, up; m) per grade, mode and filter (Fig. 4-7/4-9);
    'errins_zupt' = the ErrINSEKF with zero-velocity updates (zupt_sd m/s) while static."""
    tr = crlb_trajectory(duration_s, static_s, rate_hz)
    out = {}
    for grade in grades:
        out[grade] = {}
        for mode in modes:
            res = run_crlb(tr, grade, mode)["final"]
            res["errins_zupt"] = run_crlb(tr, grade, mode, errins_zupt_sd=zupt_sd)["final"][
                "errins"]
            out[grade][mode] = res
    return out


__all__ = [
    "GradeNoise",
    "TruthTrajectory",
    "aiding_schedule",
    "crlb_table",
    "crlb_trajectory",
    "errins_crlb",
    "gmikf_crlb",
    "grade_noise",
    "run_crlb",
]
