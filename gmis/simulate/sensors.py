"""Simulated sensors: IMU (001 eq. 4.1.39/4.1.40 with errors), GNSS position/velocity
solution of the primary antenna (eq. 4.1.41/4.1.42) and dual-antenna heading.

IMU error model per axis i (gyro in rad/s, accelerometer in m/s²), sample k at t_k:

    y_k = Q( (1 + s_i) · ideal_k + b_k + n_k ),   n_k ~ N(0, σ_wn²),  σ_wn = density/√δt
    b_k = b_0 + β_k + g_k
    β_0 = 0,  β_k+1 = β_k + σ_rw·ε_k,             σ_rw = BS·√(δt/T)  (001 Table 4-3 note)
    g_0 ~ N(0, σ_gm²),  g_k+1 = e^(−δt/τ) g_k + σ_gm √(1 − e^(−2δt/τ)) η_k

where (1 + s)·ideal + b is exactly gmis.imu_model.imu_measurement(truth, b_k, s) (the
model is (I+S)(…) + b), Q rounds to the quantisation step (0 = off), b_0 is the constant
turn-on bias, s the constant scale factor. All random draws come from per-component
generators spawned from the scenario seed, so changing one component leaves the others'
noise unchanged.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from gmis.frames import dcm_body_to_nav_into
from gmis.imu_model import imu_measurement_into
from gmis.simulate.imu_grades import G0
from gmis.simulate.trajectory import enu_to_geodetic_many

DEG = np.pi / 180.0
DEG_H = DEG / 3600.0   # rad/s per °/h
MG = 1e-3 * G0         # m/s² per mg


@njit(cache=True)
def ideal_imu_outputs(r, v_b, a_b, theta, omega_b, b_w, b_a, s_w, s_a, frame):
    """imu_measurement (001 eq. 4.1.39/4.1.40) at every sample: (N, 6) [gyro, accel]."""
    n = r.shape[0]
    out = np.empty((n, 6))
    row = np.empty(6)
    for k in range(n):
        imu_measurement_into(r[k], v_b[k], a_b[k], theta[k], omega_b[k], b_w[k], b_a[k],
                             s_w, s_a, frame, row)
        out[k] = row
    return out


@dataclass
class ImuErrorModel:
    """Per-axis IMU error parameters in SI units (rad/s, m/s², dimensionless)."""
    gyro_bias0: np.ndarray
    accel_bias0: np.ndarray
    gyro_scale: np.ndarray
    accel_scale: np.ndarray
    gyro_white_sigma: np.ndarray      # per sample
    accel_white_sigma: np.ndarray
    gyro_rw_sigma: np.ndarray         # per step
    accel_rw_sigma: np.ndarray
    gyro_gm_sigma: np.ndarray
    gyro_gm_tau: np.ndarray
    accel_gm_sigma: np.ndarray
    accel_gm_tau: np.ndarray
    gyro_quant: np.ndarray
    accel_quant: np.ndarray


def imu_error_model(imu_cfg, rate_hz, rng):
    """SI error parameters from the [imu] section; draws the turn-on bias when not given."""
    dt = 1.0 / rate_hz
    arr = lambda key: np.asarray(imu_cfg[key], float)
    t_bs = imu_cfg["bias_correlation_time_s"]
    gyro_bs = arr("gyro_bias_instability_deg_h") * DEG_H
    accel_bs = arr("accel_bias_instability_mg") * MG
    draw = rng.standard_normal(6)  # always drawn, so the stream does not depend on the keys
    gyro_b0 = (arr("gyro_bias_deg_h") * DEG_H if "gyro_bias_deg_h" in imu_cfg
               else draw[:3] * gyro_bs)
    accel_b0 = (arr("accel_bias_mg") * MG if "accel_bias_mg" in imu_cfg
                else draw[3:] * accel_bs)
    return ImuErrorModel(
        gyro_bias0=gyro_b0, accel_bias0=accel_b0,
        gyro_scale=arr("gyro_scale_ppm") * 1e-6, accel_scale=arr("accel_scale_ppm") * 1e-6,
        gyro_white_sigma=arr("gyro_arw_deg_sqrt_h") * DEG / 60.0 / np.sqrt(dt),
        accel_white_sigma=arr("accel_vrw_m_s_sqrt_h") / 60.0 / np.sqrt(dt),
        gyro_rw_sigma=gyro_bs * np.sqrt(dt / t_bs), accel_rw_sigma=accel_bs * np.sqrt(dt / t_bs),
        gyro_gm_sigma=arr("gyro_gm_sigma_deg_h") * DEG_H, gyro_gm_tau=arr("gyro_gm_tau_s"),
        accel_gm_sigma=arr("accel_gm_sigma_mg") * MG, accel_gm_tau=arr("accel_gm_tau_s"),
        gyro_quant=arr("gyro_quantization_deg_s") * DEG,
        accel_quant=arr("accel_quantization_mg") * MG)


@njit(cache=True)
def gauss_markov_series(x0, phi, q, eps):
    """g_0 = x0, g_k+1 = φ g_k + q ε_k, per column (first-order Gauss-Markov, exact
    discretisation)."""
    n, m = eps.shape
    out = np.empty((n, m))
    out[0] = x0
    for k in range(1, n):
        for i in range(m):
            out[k, i] = phi[i] * out[k - 1, i] + q[i] * eps[k - 1, i]
    return out


def bias_series(b0, rw_sigma, gm_sigma, gm_tau, dt, n, rng):
    """b_k = b_0 + random walk + Gauss-Markov drift, (n, 3)."""
    steps = rng.standard_normal((n, 3))
    gm_eps = rng.standard_normal((n, 3))
    gm0 = rng.standard_normal(3) * gm_sigma
    rw = np.zeros((n, 3))
    np.cumsum(steps[:-1] * rw_sigma, axis=0, out=rw[1:])
    phi = np.exp(-dt / gm_tau)
    gm = gauss_markov_series(gm0, phi, gm_sigma * np.sqrt(1.0 - phi * phi), gm_eps)
    return b0 + rw + gm


def quantize(x, step):
    """Round each column to a multiple of its step (step 0 = unchanged)."""
    out = x.copy()
    for i, q in enumerate(step):
        if q > 0.0:
            out[:, i] = q * np.round(x[:, i] / q)
    return out


@dataclass
class ImuSimulation:
    gyro: np.ndarray          # (N,3) rad/s, body RFU
    accel: np.ndarray         # (N,3) m/s²
    gyro_bias: np.ndarray     # (N,3) true bias b_k (rad/s)
    accel_bias: np.ndarray
    gyro_noise: np.ndarray    # (N,3) white noise n_k added (before quantisation)
    accel_noise: np.ndarray
    model: ImuErrorModel


def simulate_imu(truth, frame, imu_cfg, rate_hz, rng_bias, rng_noise):
    dt = 1.0 / rate_hz
    n = truth.t_s.size
    m = imu_error_model(imu_cfg, rate_hz, rng_bias)
    bg = bias_series(m.gyro_bias0, m.gyro_rw_sigma, m.gyro_gm_sigma, m.gyro_gm_tau, dt, n,
                     rng_bias)
    ba = bias_series(m.accel_bias0, m.accel_rw_sigma, m.accel_gm_sigma, m.accel_gm_tau, dt, n,
                     rng_bias)
    ideal = ideal_imu_outputs(truth.r_enu, truth.v_b, truth.a_b, truth.euler, truth.omega_b,
                              bg, ba, m.gyro_scale, m.accel_scale, frame)
    eps = rng_noise.standard_normal((n, 6))
    ng = eps[:, :3] * m.gyro_white_sigma
    na = eps[:, 3:] * m.accel_white_sigma
    gyro = quantize(ideal[:, :3] + ng, m.gyro_quant)
    accel = quantize(ideal[:, 3:] + na, m.accel_quant)
    return ImuSimulation(gyro, accel, bg, ba, ng, na, m)


def epoch_indices(t_s, imu_rate_hz, rate_hz, outages):
    """IMU sample indices of the sensor epochs (every imu_rate/rate samples) and the mask of
    epochs kept (outside every [start_s, end_s) outage window)."""
    step = round(imu_rate_hz / rate_hz)
    idx = np.arange(0, t_s.size, step)
    keep = np.ones(idx.size, bool)
    for o in outages:
        keep &= ~((t_s[idx] >= o["start_s"]) & (t_s[idx] < o["end_s"]))
    return idx, keep


@njit(cache=True)
def antenna_position_velocity(r, v_b, theta, omega_b, lever):
    """r_ant = r + C_b^n L (001 eq. 4.1.41), v_ant = C_b^n (v^b + ω×L) (eq. 4.1.42)."""
    n = r.shape[0]
    pos = np.empty((n, 3))
    vel = np.empty((n, 3))
    c = np.empty((3, 3))
    wl = np.empty(3)
    for k in range(n):
        dcm_body_to_nav_into(theta[k, 0], theta[k, 1], theta[k, 2], c)
        w = omega_b[k]
        wl[0] = w[1] * lever[2] - w[2] * lever[1]
        wl[1] = w[2] * lever[0] - w[0] * lever[2]
        wl[2] = w[0] * lever[1] - w[1] * lever[0]
        for i in range(3):
            pos[k, i] = r[k, i] + c[i, 0] * lever[0] + c[i, 1] * lever[1] + c[i, 2] * lever[2]
            vel[k, i] = (c[i, 0] * (v_b[k, 0] + wl[0]) + c[i, 1] * (v_b[k, 1] + wl[1])
                         + c[i, 2] * (v_b[k, 2] + wl[2]))
    return pos, vel


@dataclass
class GnssSimulation:
    index: np.ndarray         # IMU sample index of each kept epoch
    llh: np.ndarray           # (M,3) noisy antenna [rad, rad, m]
    vel_enu: np.ndarray       # (M,3) noisy antenna velocity m/s
    pos_sigma: np.ndarray     # (3,) m ENU
    vel_sigma: np.ndarray     # (3,) m/s
    true_r_enu: np.ndarray    # (M,3) true antenna position (origin ENU)
    true_vel_enu: np.ndarray  # (M,3)
    pos_noise_enu: np.ndarray
    vel_noise_enu: np.ndarray


def simulate_gnss(truth, frame, gnss_cfg, imu_rate_hz, rng):
    """Primary-antenna solution; position noise is added in the origin ENU frame. With
    velocity_latency_s the velocity (and true_vel_enu) is the antenna's that many IMU
    periods (rounded) before the fix's sample, the first sample at the start."""
    idx, keep = epoch_indices(truth.t_s, imu_rate_hz, gnss_cfg["rate_hz"], gnss_cfg["outage"])
    lever = np.asarray(gnss_cfg["lever_arm_m"], float)
    pos, vel = antenna_position_velocity(truth.r_enu[idx], truth.v_b[idx], truth.euler[idx],
                                         truth.omega_b[idx], lever)
    lag = round(gnss_cfg.get("velocity_latency_s", 0.0) * imu_rate_hz)
    if lag:
        v_idx = np.maximum(idx - lag, 0)
        _, vel = antenna_position_velocity(truth.r_enu[v_idx], truth.v_b[v_idx],
                                           truth.euler[v_idx], truth.omega_b[v_idx], lever)
    ps = np.asarray(gnss_cfg["position_sigma_m"], float)
    vs = np.asarray(gnss_cfg["velocity_sigma_m_s"], float)
    pn = rng.standard_normal((idx.size, 3)) * ps
    vn = rng.standard_normal((idx.size, 3)) * vs
    pos, vel, pn, vn, idx = pos[keep], vel[keep], pn[keep], vn[keep], idx[keep]
    llh = enu_to_geodetic_many(frame, pos + pn)
    return GnssSimulation(idx, llh, vel + vn, ps, vs, pos, vel, pn, vn)


@dataclass
class HeadingSimulation:
    index: np.ndarray
    heading: np.ndarray       # (M,) rad in [0, 2π), azimuth of the body forward axis
    sigma: float              # rad
    noise: np.ndarray


def simulate_heading(truth, heading_cfg, imu_rate_hz, rng):
    idx, keep = epoch_indices(truth.t_s, imu_rate_hz, heading_cfg["rate_hz"],
                              heading_cfg["outage"])
    sigma = heading_cfg["sigma_deg"] * DEG
    noise = rng.standard_normal(idx.size) * sigma
    idx, noise = idx[keep], noise[keep]
    return HeadingSimulation(idx, np.mod(truth.euler[idx, 2] + noise, 2.0 * np.pi), sigma,
                             noise)
