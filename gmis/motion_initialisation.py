"""Initial state of a drive that is already moving at its first sample (issue 20 item 1).

A static alignment (gmis.alignment) assumes rest: levelling from the mean specific force
then reads the vehicle's acceleration as tilt (2 m/s² ≈ 12°) and the velocity starts at
0. Here instead:

* position, velocity and acceleration of the antenna at t0 come from one weighted
  least-squares fit of the first ``fit_s`` seconds of GNSS fixes (and velocities, when
  the file has them) to a constant-jerk model per ENU axis (fit_constant_jerk), whose
  covariance (AᵀWA)⁻¹, scaled by the reduced χ² when that exceeds 1 (time-correlated
  fixes), gives the σ of r0, v0, a;
* heading ψ (azimuth, clockwise from north) from a heading stream when there is one,
  else the course atan2(v_E, v_N) of v0 (no sideslip; σ² = (σ_v⊥/|v_h|)² + sideslip²),
  else — below ``min_course_speed_m_s`` — the course of the first faster epochs carried
  back by the gyro (gmis.course_heading);
* pitch and roll from the mean specific force over the same ``fit_s`` seconds with the
  fit's acceleration (the window's least-squares mean) compensated, at the heading of the
  window's middle (ψ0 carried by the mean gyro z rate): f^b = C_n^b (a^n − g^n) (C_n^b of 001 eq. 2.2.4; the
  specific force is acceleration minus gravitation), solved for (p, γ) at the known ψ;
  σ from the acceleration σ, the accelerometer-bias σ and the ψ error times the
  horizontal acceleration, all over |g|;
* the angular-rate state from the mean gyro (the gyro bias is unknown in motion: it
  keeps its [initial_sigma] σ, which is also added to the rate σ).

Lever arm: the antenna velocity is taken as the IMU velocity (ω × l neglected; 5 cm at
0.3 rad/s is 1.5 cm/s, inside the fit σ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from gmis.frames import dcm_body_to_nav
from gmis.gravity import gravity_nav_into

SIDESLIP_SIGMA_RAD = np.radians(1.5)  # car course − heading, normal driving
MIN_COURSE_SPEED_M_S = 3.0  # below this the course at t0 is not used as the heading


@dataclass(frozen=True)
class KinematicFit:
    """Antenna ENU position r0 (m), velocity v0 (m/s), acceleration a (m/s²) at t0, the
    mean acceleration a_mean (m/s²) over [t0, t0 + fit_s], and their 1σ (3,) each;
    n_epochs fixes used; chi2_scale ≥ 1 applied to the σ."""

    r0: np.ndarray
    v0: np.ndarray
    a: np.ndarray
    a_mean: np.ndarray
    r0_sd: np.ndarray
    v0_sd: np.ndarray
    a_sd: np.ndarray
    a_mean_sd: np.ndarray
    n_epochs: int
    chi2_scale: float


def fit_constant_jerk(t, pos_enu, pos_sd, t0, fit_s=1.0, vel_enu=None, vel_sd=None,
                      min_epochs=5, correlated=None):
    """Weighted LSQ over the GNSS epochs in [t0, t0 + fit_s] (at least min_epochs: the
    window grows to the first min_epochs epochs) of, per ENU axis,
        r(τ) = r0 + v0 τ + a τ²/2 + j τ³/6,   v(τ) = v0 + a τ + j τ²/2,   τ = t − t0
    (a cubic: an acceleration that changes inside the window — a car pulling away — would
    bias a constant-acceleration fit's v0 and a). a_mean = a + j fit_s/2 is the mean
    acceleration over the window, the one the mean specific force sees. Covariance
    (AᵀWA)⁻¹ times the reduced χ² when that exceeds 1. None with fewer epochs.

    correlated = (σ_b (3,) m, τ s): the fixes also carry a first-order Gauss-Markov error
    (gmis.gnss_error_states) with covariance C_b[k, l] = σ_b² e^{−|t_k − t_l|/τ}, which the
    white-noise covariance misses (a slowly wandering fix looks like motion): with the
    estimator x̂ = M y, M = (AᵀWA)⁻¹AᵀW, M_r C_b M_rᵀ (M_r: its position columns) is added to
    the covariance of v0, a and a_mean — not of r0, whose error −b(t0) the filter carries
    in its error states (gmis.run_filter.with_gnss_error_states)."""
    k = np.flatnonzero(t >= t0)
    if k.size < min_epochs:
        return None
    in_win = k[t[k] <= t0 + fit_s + 1e-9]
    k = in_win if in_win.size >= min_epochs else k[:min_epochs]
    tau = t[k] - t0
    est = np.zeros((3, 4))
    sd = np.zeros((3, 4))
    to_mean = np.array([0.0, 0.0, 1.0, 0.5 * fit_s])
    worst = 1.0
    for axis in range(3):
        rows = [np.column_stack([np.ones_like(tau), tau, tau ** 2 / 2, tau ** 3 / 6])]
        y = [pos_enu[k, axis]]
        w = [pos_sd[k, axis]]
        if vel_enu is not None:
            rows.append(np.column_stack([np.zeros_like(tau), np.ones_like(tau), tau,
                                         tau ** 2 / 2]))
            y.append(vel_enu[k, axis])
            w.append(vel_sd[k, axis])
        a_mat = np.vstack(rows) / np.concatenate(w)[:, None]
        b = np.concatenate(y) / np.concatenate(w)
        x, *_ = np.linalg.lstsq(a_mat, b, rcond=None)
        cov = np.linalg.inv(a_mat.T @ a_mat)
        dof = a_mat.shape[0] - 4
        scale = max(1.0, float(np.sum((a_mat @ x - b) ** 2)) / dof) if dof > 0 else 1.0
        worst = max(worst, scale)
        m_pos = (cov @ a_mat.T)[:, :tau.size] / pos_sd[k, axis][None, :]
        cov *= scale
        if correlated is not None:
            sigma_b, tau_b = correlated
            c_b = sigma_b[axis] ** 2 * np.exp(-np.abs(tau[:, None] - tau[None, :]) / tau_b)
            extra = m_pos @ c_b @ m_pos.T
            extra[0, :] = extra[:, 0] = 0.0
            cov += extra
        est[axis] = [x[0], x[1], x[2], to_mean @ x]
        sd[axis] = np.sqrt([cov[0, 0], cov[1, 1], cov[2, 2], to_mean @ cov @ to_mean])
    return KinematicFit(est[:, 0], est[:, 1], est[:, 2], est[:, 3], sd[:, 0], sd[:, 1],
                        sd[:, 2], sd[:, 3], int(k.size), worst)


def level_in_motion(f_body, acc_enu, gravity_enu, heading):
    """(pitch, roll) rad with C_n^b (acc − g) = f_body at the given heading (least squares
    over the two angles, started from the static levelling of f_body)."""
    u = np.asarray(acc_enu, float) - np.asarray(gravity_enu, float)
    p0 = np.arcsin(np.clip(f_body[1] / np.linalg.norm(f_body), -1.0, 1.0))
    r0 = np.arctan2(-f_body[0], f_body[2])

    def residual(x):
        return dcm_body_to_nav(x[0], x[1], heading).T @ u - f_body

    sol = least_squares(residual, [p0, r0], xtol=1e-12, ftol=1e-12)
    pitch, roll = float(sol.x[0]), float(np.arctan2(np.sin(sol.x[1]), np.cos(sol.x[1])))
    return pitch, roll


@dataclass(frozen=True)
class InMotionStart:
    """IMU-centre state at t0 and its 1σ, and the note printed about it."""

    pos_enu: np.ndarray       # (3,) m, IMU centre
    vel_body: np.ndarray      # (3,) m/s, v^b
    acc_body: np.ndarray      # (3,) m/s², a^b
    attitude: np.ndarray      # (3,) pitch, roll, heading rad
    rate_body: np.ndarray     # (3,) rad/s, ω^b (mean gyro)
    pos_sd: np.ndarray
    vel_sd: np.ndarray
    acc_sd: np.ndarray
    att_sd: np.ndarray
    rate_sd: np.ndarray
    n_imu_samples: int
    accel_std: np.ndarray     # (3,) spread of the levelling samples (m/s²)
    gyro_std: np.ndarray
    note: str


def _body_sd(c_bn, sd_enu):
    """1σ per body axis of a vector known with independent ENU 1σ sd_enu."""
    return np.sqrt((c_bn.T ** 2) @ (np.asarray(sd_enu) ** 2))


def in_motion_start(frame, gnss_t, ant_enu, pos_sd, imu_t, gyro, accel, t0, lever_arm,
                    gyro_bias_sd, accel_bias_sd, vel_enu=None, vel_sd=None, heading=None,
                    heading_sd=None, course_carried=None, fit_s=2.0, correlated=None):
    """The initial state of the module docstring, or None when the GNSS gives no fit.

    frame: gmis.earth.make_nav_frame; gnss_t (M,) s, ant_enu (M,3) antenna ENU m, pos_sd
    (M,3) m, vel_enu / vel_sd (M,3) m/s or None; imu_t (N,), gyro rad/s, accel m/s² (N,3)
    body RFU; lever_arm (3,) body m IMU → antenna; gyro_bias_sd / accel_bias_sd (3,) the
    a-priori bias σ; heading / heading_sd (rad) from a heading stream, or None;
    course_carried: a callable () → (heading, σ) or None for a slow start; correlated:
    (σ_b, τ) of Gauss-Markov fix errors (fit_constant_jerk)."""
    fit = fit_constant_jerk(gnss_t, ant_enu, pos_sd, t0, fit_s, vel_enu, vel_sd,
                            correlated=correlated)
    if fit is None:
        return None
    speed = float(np.hypot(fit.v0[0], fit.v0[1]))
    if heading is not None:
        how = "the heading stream"
    elif speed >= MIN_COURSE_SPEED_M_S:
        heading = float(np.arctan2(fit.v0[0], fit.v0[1]) % (2 * np.pi))
        # σ of the velocity across the track, over the speed
        across = np.array([np.cos(heading), -np.sin(heading)])
        sd_across = float(np.sqrt(np.sum((across * fit.v0_sd[:2]) ** 2)))
        heading_sd = float(np.hypot(sd_across / speed, SIDESLIP_SIGMA_RAD))
        how = f"the GNSS course at {speed:.1f} m/s"
    else:
        got = course_carried() if course_carried is not None else None
        if got is None:
            return None
        heading, heading_sd = got
        how = "the course of the first faster epochs carried back by the gyro"

    sel = (imu_t >= t0) & (imu_t < t0 + fit_s)
    if sel.sum() < 2:
        sel = np.zeros(imu_t.size, bool)
        sel[:2] = True
    f_body = accel[sel].mean(axis=0)
    g_enu, dg = np.zeros(3), np.zeros((3, 3))
    gravity_nav_into(frame, fit.r0, g_enu, dg)
    g = float(np.linalg.norm(g_enu))
    # body z up: a positive rate turns left, i.e. decreases the azimuth
    heading_mid = heading - float(gyro[sel, 2].mean()) * 0.5 * fit_s
    pitch, roll = level_in_motion(f_body, fit.a_mean, g_enu, heading_mid)
    a_h = float(np.hypot(fit.a[0], fit.a[1]))
    noise_of_mean = accel[sel].std(axis=0) / np.sqrt(sel.sum())
    tilt_sd = np.sqrt(np.max(fit.a_mean_sd[:2]) ** 2 + np.max(accel_bias_sd[:2]) ** 2
                      + np.max(noise_of_mean[:2]) ** 2 + (a_h * heading_sd) ** 2) / g

    c_bn = dcm_body_to_nav(pitch, roll, heading)
    arm_sd = np.linalg.norm(lever_arm) * max(tilt_sd, heading_sd)
    rate = gyro[sel].mean(axis=0)
    rate_sd = np.sqrt(np.asarray(gyro_bias_sd) ** 2
                      + (gyro[sel].std(axis=0) / np.sqrt(sel.sum())) ** 2)
    att_sd = np.array([tilt_sd, tilt_sd, heading_sd])
    note = (f"the data start in motion ({speed:.1f} m/s at t={t0:.2f} s): initial position, "
            f"velocity and acceleration from {fit.n_epochs} GNSS epochs (1 sigma "
            f"{np.max(fit.r0_sd):.2f} m, {np.max(fit.v0_sd):.2f} m/s), heading "
            f"{np.degrees(heading):.1f} deg from {how} (1 sigma "
            f"{np.degrees(heading_sd):.1f} deg), pitch/roll {np.degrees(pitch):.1f}/"
            f"{np.degrees(roll):.1f} deg from the specific force minus the GNSS acceleration "
            f"(1 sigma {np.degrees(tilt_sd):.2f} deg); no static alignment, gyro bias 0")
    return InMotionStart(
        pos_enu=fit.r0 - c_bn @ np.asarray(lever_arm, float),
        vel_body=c_bn.T @ fit.v0, acc_body=c_bn.T @ fit.a,
        attitude=np.array([pitch, roll, heading]), rate_body=rate,
        pos_sd=np.hypot(fit.r0_sd, arm_sd), vel_sd=_body_sd(c_bn, fit.v0_sd) + speed * max(
            tilt_sd, heading_sd),
        acc_sd=_body_sd(c_bn, fit.a_sd) + a_h * heading_sd,
        att_sd=att_sd, rate_sd=rate_sd, n_imu_samples=int(sel.sum()),
        accel_std=accel[sel].std(axis=0), gyro_std=gyro[sel].std(axis=0), note=note)
