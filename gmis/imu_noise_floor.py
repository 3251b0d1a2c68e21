"""The IMU measurement σ never below the noise the IMU shows at rest.

In the GMIKF the IMU is a measurement (001 eq. 4.1.39/4.1.40) with 1σ ``imu_sd``. While the
vehicle is static the true rate and specific force are constant, so the spread of the
samples in the static alignment window is the sensor's white noise plus what the engine
or the road adds (vibration) — a lower bound of the σ the filter must use. A recipe σ below
it (001 Table 6-2's 0.75 deg/s against 2.4 deg/s of idle vibration on the real car drive)
makes the outlier tests reject a large share of the samples at rest; the accepted ones are a
truncated, not necessarily symmetric, sample and bias the gyro-bias estimate while the
process noise is frozen (1.8 deg/s on that drive, which then diverged once it moved).

``imu_noise_floor`` raises an axis to the measured spread s (the IMU's noise at rest) when
s is significantly larger than the recipe σ — one-sided χ² test at level 0.001 on the N
samples, s > σ (1 + 3.09 / √(2(N − 1))) (normal approximation of √(χ²/(N−1))) — so an IMU
that matches its σ is left alone; it says so on the terminal.
``[filter].imu_noise_from_static = false`` keeps the recipe's values.
"""

import numpy as np

AXIS_NAMES = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
MIN_SAMPLES = 200  # fewer samples in the static window: no floor (too uncertain)
Z_ONE_SIDED_0001 = 3.090232  # standard normal quantile 1 − 0.001


def imu_noise_floor(imu_sd, gyro_std_rad_s, accel_std_m_s2, n_samples: int,
                    window_s: float):
    """(6,) σ = max(imu_sd, measured spread) per axis and the note to print (None when
    nothing changed). imu_sd: (6,) gyro rad/s, accel m/s²; gyro_std_rad_s, accel_std_m_s2:
    (3,) sample standard deviations in the static window of window_s s with n_samples."""
    imu_sd = np.asarray(imu_sd, dtype=float)
    if n_samples < MIN_SAMPLES:
        return imu_sd.copy(), None
    measured = np.concatenate([np.asarray(gyro_std_rad_s, float),
                               np.asarray(accel_std_m_s2, float)])
    threshold = imu_sd * (1.0 + Z_ONE_SIDED_0001 / np.sqrt(2.0 * (n_samples - 1)))
    raised = measured > threshold
    if not raised.any():
        return imu_sd.copy(), None
    out = np.where(raised, measured, imu_sd)
    parts = []
    for i in np.flatnonzero(raised):
        if i < 3:
            parts.append(f"{AXIS_NAMES[i]} {np.degrees(imu_sd[i]):.3g} -> "
                         f"{np.degrees(out[i]):.3g} deg/s")
        else:
            parts.append(f"{AXIS_NAMES[i]} {imu_sd[i]:.3g} -> {out[i]:.3g} m/s^2")
    note = (f"IMU noise at rest (static window {window_s:.1f} s, {n_samples} samples) exceeds "
            f"the [noise] sigma: {', '.join(parts)}; the filter uses the measured values "
            "([filter].imu_noise_from_static = false keeps the recipe's)")
    return out, note


__all__ = ["imu_noise_floor"]
