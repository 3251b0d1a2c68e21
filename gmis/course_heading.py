"""Initial heading of a single-antenna vehicle from the GNSS course over ground.

Once the vehicle moves at ≥ min_speed_m_s, the course ψ_c = atan2(v_E, v_N) (azimuth,
clockwise from north, rad) of the first such GNSS epochs is taken as the heading of the
forward axis there (no sideslip), and carried back to the alignment time t0 through the
gyro's body-z rate: ψ(t0) = ψ_c(t1) + ∫_{t0}^{t1} (ω_z − b_z) dt (body RFU, z up: a
positive ω_z turns left, i.e. decreases the azimuth; tilt neglected). The returned 1σ
(rad) covers the sideslip / course noise at low speed.
"""

from __future__ import annotations

import numpy as np

COURSE_HEADING_SIGMA_RAD = np.radians(5.0)


def heading_from_course(gnss_t, vel_enu, imu_t, gyro_z, gyro_bias_z, t0,
                        min_speed_m_s=2.0, n_epochs=4):
    """(heading at t0 rad, 1σ rad, course epoch time s) or None when the vehicle never
    reaches min_speed_m_s. vel_enu (M,3) m/s at gnss_t; gyro_z (N,) rad/s at imu_t."""
    speed = np.hypot(vel_enu[:, 0], vel_enu[:, 1])
    k = np.flatnonzero((gnss_t >= t0) & (speed >= min_speed_m_s))[:n_epochs]
    if k.size == 0:
        return None
    course = np.arctan2(vel_enu[k, 0], vel_enu[k, 1])
    course_mean = float(np.arctan2(np.sin(course).mean(), np.cos(course).mean()))
    t1 = float(gnss_t[k].mean())
    sel = (imu_t >= t0) & (imu_t <= t1)
    turned = float(np.trapezoid(gyro_z[sel] - gyro_bias_z, imu_t[sel])) if sel.sum() > 1 \
        else 0.0
    return (course_mean + turned) % (2 * np.pi), float(COURSE_HEADING_SIGMA_RAD), t1
