"""The one translation from a validated recipe (gmis.recipe.Recipe, SI/rad) to the
configuration of every engine:

    gmikf_config(recipe)         GmikfConfig   loosely/tightly coupled GMIKF (gmis.run_filter)
    tc_config(recipe)            TcConfig      DD observable groups of the tightly coupled
                                               filter (gmis.tc)
    errins_config(recipe)        ErrInsConfig  conventional error-state INS/GNSS EKF
                                               (gmis.errins)
    rtk_config(recipe)           RtkConfig     GNSS-only RTK (gnss.rtk), from [rtk]
    tc_gnss_only_config(rtk)     TcConfig      `gmis rtk --tight` (gmis.tc_gnss_only), from
                                               rtk_config(recipe)

Which recipe value drives which engine field is listed once per noise value in
gmis.noise_registry; this module applies it. The engine config classes live with their
engines and are imported inside the functions, so that reading a loosely coupled recipe
does not import the GNSS engines.
"""

from __future__ import annotations

import math

import numpy as np

from gmis.noise_registry import BIAS_MODEL_KEYS, tc_sigma_fields
from gmis.recipe import Recipe


def bias_drift_noise(noise, step_s: float):
    """Per sensor (gyro, accel): (drift 1σ per step of step_s s (3,), 1/τ (3,) 1/s) of
    the bias states. random_walk: the [noise] drift sigmas, 1/τ = 0; gauss_markov: the
    driving noise σ√(2 step_s/τ), whose density σ²·2/τ gives the Gauss-Markov process of
    stationary variance σ² (gmis.system_model.drift_noise_variance)."""
    out = []
    for k in BIAS_MODEL_KEYS:
        if getattr(noise, k.model_field) == "gauss_markov":
            tau = np.asarray(getattr(noise, k.tau), dtype=float)
            sigma = np.asarray(getattr(noise, k.sigma), dtype=float)
            if not (np.all(tau > 0) and np.all(sigma > 0)):
                raise ValueError(f"{k.model_key} = gauss_markov needs {k.tau} and {k.sigma} "
                                 f"> 0, got {tau.tolist()}, {sigma.tolist()}")
            out.append((sigma * np.sqrt(2.0 * step_s / tau), 1.0 / tau))
        elif any(t != 0 for t in getattr(noise, k.tau)):
            raise ValueError(f"{k.tau}: all three τ > 0 (Gauss-Markov) or all 0 (random "
                             f"walk), got {getattr(noise, k.tau)}")
        else:
            out.append((np.asarray(getattr(noise, k.drift), dtype=float), np.zeros(3)))
    return out


def gmikf_config(recipe: Recipe):
    """GMIKF configuration (per-step process noise q_sd (001 Table 6-2), IMU noise imu_sd,
    initial 1σ p0_sd in the order of gmis.state, lever arm, outlier level, non-holonomic
    constraint) from the recipe's [noise], [initial_sigma], [antennas], [filter] and
    [nonholonomic]."""
    from gmis.run_filter import GmikfConfig

    nz = recipe.noise
    n_imu = recipe.filter.states
    (bg_sd, bg_inv_tau), (ba_sd, ba_inv_tau) = bias_drift_noise(nz, 1.0 / GmikfConfig.q_rate_hz)
    q = [*nz.jerk_sigma_m_s3, *nz.angular_acceleration_sigma_rad_s2, *bg_sd, *ba_sd]
    inv_tau = [*bg_inv_tau, *ba_inv_tau]
    if n_imu == 27:
        q += [*nz.gyro_scale_drift_sigma, *nz.accel_scale_drift_sigma]
        inv_tau += [0.0] * 6
    s = recipe.initial_sigma
    p0 = [*s.position_m, *s.velocity_m_s, *s.acceleration_m_s2, *s.attitude_rad,
          *s.angular_rate_rad_s, *s.gyro_bias_rad_s, *s.accel_bias_m_s2]
    if n_imu == 27:
        p0 += [*s.gyro_scale, *s.accel_scale]
    nhc = recipe.nonholonomic
    nhc_args = {} if nhc is None else {
        "nhc_sd": np.array([nhc.sigma_lateral_m_s, nhc.sigma_vertical_m_s]),
        "nhc_interval_s": 1.0 / nhc.rate_hz, "nhc_lever_arm": np.array(nhc.lever_arm_m)}
    return GmikfConfig(n_imu=n_imu, q_sd=np.array(q), imu_sd=np.array(
        [*nz.gyro_sigma_rad_s, *nz.accel_sigma_m_s2]),
        lever_arm=np.array(recipe.antennas.primary_lever_arm_m), p0_sd=np.array(p0),
        outlier_alpha=recipe.filter.outlier_alpha, consider_scale_imu=True,
        reopen_after=recipe.filter.reopen_after_epochs,
        imu_outlier_test=recipe.filter.imu_outlier_test,
        drift_inv_tau=np.array(inv_tau), **nhc_args, **_zupt_args(recipe),
        gnss_error_tau_s=np.full(3, recipe.gnss.error_correlation_time_s),
        gnss_error_sigma_m=np.array(recipe.gnss.error_sigma_m))


def _zupt_args(recipe: Recipe) -> dict:
    """GmikfConfig ZUPT/ZARU fields of the [zupt] section (none: off). Thresholds not given:
    |f| spread 2 max(σ_accel) + 0.02 m/s² (the white noise plus idle vibration); mean rate
    0.3 °/s + 3 max(σ_gyro)/√(samples per window)."""
    z = recipe.zupt
    if z is None:
        return {}
    from gmis.motion import StopDetector
    nz = recipe.noise
    accel = z.accel_std_threshold_m_s2 if z.accel_std_threshold_m_s2 is not None else \
        2.0 * max(nz.accel_sigma_m_s2) + 0.02
    per_window = max(1.0, z.window_s * recipe.imu.rate_hz)
    gyro = z.gyro_threshold_rad_s if z.gyro_threshold_rad_s is not None else \
        np.radians(0.3) + 3.0 * max(nz.gyro_sigma_rad_s) / np.sqrt(per_window)
    return {"zupt_sd": np.full(3, z.sigma_velocity_m_s), "zaru_sd": np.full(3, z.sigma_rate_rad_s),
            "zupt_interval_s": 1.0 / z.rate_hz,
            "stop_detector": StopDetector(z.window_s, float(accel), float(gyro),
                                          z.gnss_speed_threshold_m_s)}


def tc_config(recipe: Recipe):
    """Tightly coupled DD configuration: σ90 of the undifferenced code, L1/L2 phase,
    Doppler and TDCP (001 eq. 5.1.8-5.1.11) from [noise], the velocity observable and
    outlier level from [filter], the success-rate gate from [rtk].min_success_rate."""
    from gmis.tc_filter import TcConfig

    sigmas = {tc_field: getattr(recipe.noise, name)
              for name, tc_field in tc_sigma_fields().items()}
    gate = recipe.rtk.min_success_rate
    return TcConfig(**sigmas, velocity_observable=recipe.filter.tc_velocity_observable,
                    outlier_alpha=recipe.filter.outlier_alpha,
                    min_success_rate=0.0 if gate is None else gate)


def errins_config(recipe: Recipe):
    """ErrINSEKF settings from the same noise figures the GMIKF reads ([noise],
    [initial_sigma]). The Euler sigmas map onto φ as: φ_E, φ_N ← max(pitch, roll) σ,
    φ_U ← heading σ."""
    from gmis.errins import ErrInsConfig
    from gmis.run_filter import GmikfConfig

    nz = recipe.noise
    s = recipe.initial_sigma
    (bg_sd, bg_inv_tau), (ba_sd, ba_inv_tau) = bias_drift_noise(nz, 1.0 / recipe.imu.rate_hz)
    # a random-walk drift in [noise] is 1σ per step of 1/q_rate_hz (100 Hz), as the GMIKF
    # reads it; the error-state INS steps at the IMU rate: σ √(q_rate / imu_rate)
    to_imu_step = math.sqrt(GmikfConfig.q_rate_hz / recipe.imu.rate_hz)
    bg_sd = np.where(bg_inv_tau > 0, bg_sd, bg_sd * to_imu_step)
    ba_sd = np.where(ba_inv_tau > 0, ba_sd, ba_sd * to_imu_step)
    tilt = max(s.attitude_rad[0], s.attitude_rad[1])
    p0 = [*s.position_m, *s.velocity_m_s, tilt, tilt, s.attitude_rad[2],
          *s.gyro_bias_rad_s, *s.accel_bias_m_s2]
    return ErrInsConfig(imu_sd=[*nz.gyro_sigma_rad_s, *nz.accel_sigma_m_s2],
                        bias_drift_sd=[*bg_sd, *ba_sd],
                        bias_tau_s=[*_tau(bg_inv_tau), *_tau(ba_inv_tau)],
                        imu_rate_hz=recipe.imu.rate_hz, p0_sd=p0,
                        lever_arm=recipe.antennas.primary_lever_arm_m,
                        outlier_alpha=recipe.filter.outlier_alpha)


def _tau(inv_tau):
    return [1.0 / v if v > 0 else math.inf for v in inv_tau]


def rtk_config(recipe: Recipe):
    """GNSS-only RTK options: the [rtk] keys the recipe gives, RtkConfig's defaults for
    the others (docs/formats.md)."""
    from gnss.rtk import RtkConfig

    return RtkConfig(**recipe.rtk.given())


def tc_gnss_only_config(rtk):
    """`gmis rtk --tight`: TcConfig with the elevation mask, ratio threshold, frequencies
    (["L1"]: no L2 phase group) and partial AR of the recipe's RtkConfig (rtk_config: [rtk], RtkConfig's
    defaults when not given), TcConfig's defaults otherwise."""
    from gmis.tc_filter import TcConfig

    return TcConfig(elevation_mask_deg=rtk.elevation_mask_deg,
                    ratio_threshold=rtk.ratio_threshold,
                    use=(True, True, rtk.dual_frequency, True),
                    partial_ar=rtk.partial_fixing, min_success_rate=rtk.min_success_rate)


__all__ = ["bias_drift_noise", "errins_config", "gmikf_config", "rtk_config", "tc_config",
           "tc_gnss_only_config"]
