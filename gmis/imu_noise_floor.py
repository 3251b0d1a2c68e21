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

A σ estimated by ``gmis vce`` from the same data (its tuned_noise.toml says
``[noise].imu_sigma_source = "vce"``) is kept: the floor guards a datasheet value or a
guess, and an estimate from the drive's own residuals is neither. On the Boulder drive VCE puts gyro x at 1.79
deg/s for the whole drive against 2.38 at idle (the engine shakes the unit more at rest
than on the road); flooring it again ran the tuned run away from the noise VCE converged
on — a different filter than the one whose residuals were estimated. The spread is still
measured and a note printed when it is significantly larger than the recipe's σ.

A drive that starts moving has no static window. ``imu_noise_in_motion`` then measures the
noise from the second differences of the samples over the first IN_MOTION_WINDOW_S:
for white noise ε of σ, Δ²ε_k = ε_{k+1} − 2ε_k + ε_{k−1} has variance 6σ², while the
vehicle's own rate or specific force changes by ẍ T² per sample pair (T = 10 ms: 1 rad/s³
of angular jerk is 1e-4 rad/s, against a gyro σ of ~0.01 rad/s), so
σ̂ = std(Δ²x)/√6 sees the noise and not the motion. The Δ² samples are an MA(2) sequence
(autocovariances 6, −4, 1 σ²), so its variance estimate from N of them is as good as one
from N·36/70 independent samples (Var ŝ² = (2/N) Σ_h γ_h²); that effective count is what
the floor's χ² test gets. On the real car drive (datasets/drive-boulder-0708) at rest
Δ² gives 2.66 / 0.44 / 0.14 deg/s and 0.091 / 0.077 / 0.142 m/s² against the sample
spread 2.39 / 0.42 / 0.13 and 0.093 / 0.074 / 0.137 (the vibration is not quite white);
over its first 20 s of motion 3.41 / 0.78 / 0.32 deg/s and 0.14 / 0.43 / 0.25 m/s² —
more than at rest, the road adds vibration.
"""

import numpy as np

AXIS_NAMES = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
MIN_SAMPLES = 200  # fewer samples in the static window: no floor (too uncertain)
Z_ONE_SIDED_0001 = 3.090232  # standard normal quantile 1 − 0.001
IN_MOTION_WINDOW_S = 20.0  # the in-motion estimate uses the first 20 s of samples
DIFF2_EFFICIENCY = 36.0 / 70.0  # effective samples per Δ² sample (module doc)


def imu_noise_in_motion(t, gyro, accel, t0, window_s=IN_MOTION_WINDOW_S):
    """White-noise σ per axis from second differences (module doc) of the samples in
    [t0, t0 + window_s): (gyro (3,) rad/s, accel (3,) m/s², effective sample count).
    t (N,) s; gyro (N, 3) rad/s; accel (N, 3) m/s²."""
    sel = (np.asarray(t) >= t0) & (np.asarray(t) < t0 + window_s)
    g, a = np.asarray(gyro, float)[sel], np.asarray(accel, float)[sel]
    if g.shape[0] < 4:
        return np.zeros(3), np.zeros(3), 0
    sd = [np.diff(x, 2, axis=0).std(axis=0) / np.sqrt(6.0) for x in (g, a)]
    return sd[0], sd[1], int((g.shape[0] - 2) * DIFF2_EFFICIENCY)


def imu_noise_floor(imu_sd, gyro_std_rad_s, accel_std_m_s2, n_samples: int,
                    window_s: float, in_motion: bool = False, explicit=(False,) * 6):
    """(6,) σ = max(imu_sd, measured spread) per axis and the note to print (None when
    nothing changed). imu_sd: (6,) gyro rad/s, accel m/s²; gyro_std_rad_s, accel_std_m_s2:
    (3,) sample standard deviations in the static window of window_s s with n_samples
    (in_motion: the second-difference estimates of imu_noise_in_motion over its first
    window_s s, n_samples its effective count). explicit: (6,) bool, the axes whose σ the
    recipe sets itself — kept, and named in the note (module doc)."""
    imu_sd = np.asarray(imu_sd, dtype=float)
    if n_samples < MIN_SAMPLES:
        return imu_sd.copy(), None
    measured = np.concatenate([np.asarray(gyro_std_rad_s, float),
                               np.asarray(accel_std_m_s2, float)])
    threshold = imu_sd * (1.0 + Z_ONE_SIDED_0001 / np.sqrt(2.0 * (n_samples - 1)))
    above = measured > threshold
    if not above.any():
        return imu_sd.copy(), None
    explicit = np.asarray(explicit, dtype=bool)
    raised = above & ~explicit
    out = np.where(raised, measured, imu_sd)
    parts, kept = [], []
    for i in np.flatnonzero(above & explicit):
        kept.append(f"{AXIS_NAMES[i]} {_value(imu_sd[i], i)} (measured {_value(measured[i], i)})")
    for i in np.flatnonzero(raised):
        if i < 3:
            parts.append(f"{AXIS_NAMES[i]} {np.degrees(imu_sd[i]):.3g} -> "
                         f"{np.degrees(out[i]):.3g} deg/s")
        else:
            parts.append(f"{AXIS_NAMES[i]} {imu_sd[i]:.3g} -> {out[i]:.3g} m/s^2")
    where = (f"in motion (second differences over the first {window_s:.1f} s, "
             f"{n_samples} effective samples)" if in_motion else
             f"at rest (static window {window_s:.1f} s, {n_samples} samples)")
    notes = []
    if parts:
        notes.append(f"IMU noise {where} exceeds the [noise] sigma: {', '.join(parts)}; the "
                     "filter uses the measured values ([filter].imu_noise_from_static = "
                     "false keeps the recipe's)")
    if kept:
        notes.append(f"IMU noise {where} exceeds the VCE-estimated sigma "
                     f"([noise].imu_sigma_source = \"vce\"): {', '.join(kept)}; kept as "
                     "estimated")
    return out, "; ".join(notes)


def _value(v, axis):
    return f"{np.degrees(v):.3g} deg/s" if axis < 3 else f"{v:.3g} m/s^2"


__all__ = ["imu_noise_floor", "imu_noise_in_motion"]
