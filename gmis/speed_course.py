"""Speed over ground and course: the velocity measurement of a receiver that gives no
vertical velocity (issue 20; u-blox NMEA/UBX gSpeed + headMot, phone location APIs).

The antenna velocity of the loosely coupled model (001 eq. 4.1.42),
    v_ant = C_b^n (v^b + ω×L)                                      (m/s, ENU)
seen through its horizontal part only:
    s = √(v_E² + v_N²)                                             (m/s, speed over ground)
    χ = atan2(v_E, v_N)                                            (rad, course, clockwise
                                                                    from north)
Jacobian by the chain rule from the E and N rows J_E, J_N of ∂v_ant/∂x:
    ∂s/∂x = (v_E J_E + v_N J_N) / s
    ∂χ/∂x = (v_N J_E − v_E J_N) / s²
The course innovation is wrapped to [−π, π) (gmis.gmikf.innovations). Both rows are
singular at s = 0: below MIN_PREDICTED_SPEED_M_S of predicted speed the rows are not
formed (the function returns False), and a course whose 1σ is not finite and > 0 is
absent (gmis.readers marks the course of slow epochs so, [gnss].course_min_speed_m_s).
No vertical velocity is invented: the vertical channel is left to the position fixes.
Tested against central differences in tests/test_speed_course.py.
"""

import numpy as np
from numba import njit

from gmis.frames import dcm_body_to_nav_into, dcm_body_to_nav_partials_into
from gmis.state import I_HEADING, I_PITCH, I_RATE, I_ROLL, I_VEL

MIN_PREDICTED_SPEED_M_S = 0.05


@njit(cache=True)
def speed_course_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """h = [s, χ] of the antenna (module doc) into h_out[h_row0:h_row0+2] and the
    Jacobian rows into jac[row0:row0+2, :]; False (rows untouched) when the predicted
    speed is below MIN_PREDICTED_SPEED_M_S."""
    c = np.empty((3, 3))
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_into(x[I_PITCH], x[I_ROLL], x[I_HEADING], c)
    dcm_body_to_nav_partials_into(x[I_PITCH], x[I_ROLL], x[I_HEADING], dc[0], dc[1], dc[2])
    lx, ly, lz = lever_arm[0], lever_arm[1], lever_arm[2]
    wx, wy, wz = x[I_RATE], x[I_RATE + 1], x[I_RATE + 2]
    u0 = x[I_VEL] + wy * lz - wz * ly
    u1 = x[I_VEL + 1] + wz * lx - wx * lz
    u2 = x[I_VEL + 2] + wx * ly - wy * lx
    ve = c[0, 0] * u0 + c[0, 1] * u1 + c[0, 2] * u2
    vn = c[1, 0] * u0 + c[1, 1] * u1 + c[1, 2] * u2
    s2 = ve * ve + vn * vn
    s = np.sqrt(s2)
    if s < MIN_PREDICTED_SPEED_M_S:
        return False
    for r in range(2):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    h_out[h_row0] = s
    h_out[h_row0 + 1] = np.arctan2(ve, vn) % (2.0 * np.pi)
    # ∂(ω×L)/∂ω = −[L×]: columns of ∂u/∂ω
    du_dw = ((0.0, lz, -ly), (-lz, 0.0, lx), (ly, -lx, 0.0))
    fs_e, fs_n = ve / s, vn / s            # ∂s/∂(v_E, v_N)
    fc_e, fc_n = vn / s2, -ve / s2         # ∂χ/∂(v_E, v_N)
    for k in range(3):
        je = c[0, k]
        jn = c[1, k]
        jac[row0, I_VEL + k] = fs_e * je + fs_n * jn
        jac[row0 + 1, I_VEL + k] = fc_e * je + fc_n * jn
        je = c[0, 0] * du_dw[0][k] + c[0, 1] * du_dw[1][k] + c[0, 2] * du_dw[2][k]
        jn = c[1, 0] * du_dw[0][k] + c[1, 1] * du_dw[1][k] + c[1, 2] * du_dw[2][k]
        jac[row0, I_RATE + k] = fs_e * je + fs_n * jn
        jac[row0 + 1, I_RATE + k] = fc_e * je + fc_n * jn
    for m in range(3):
        d = dc[m]
        je = d[0, 0] * u0 + d[0, 1] * u1 + d[0, 2] * u2
        jn = d[1, 0] * u0 + d[1, 1] * u1 + d[1, 2] * u2
        jac[row0, I_PITCH + m] = fs_e * je + fs_n * jn
        jac[row0 + 1, I_PITCH + m] = fc_e * je + fc_n * jn
    return True


def speed_course_from_enu(vel_enu):
    """(speed m/s, course rad in [0, 2π)) of ENU velocities (M, 3) — simulator and test
    helper; the vertical component is ignored."""
    v = np.asarray(vel_enu, dtype=float)
    return np.hypot(v[:, 0], v[:, 1]), np.arctan2(v[:, 0], v[:, 1]) % (2.0 * np.pi)


def horizontal_velocity(speed, course):
    """(M, 2) [v_E, v_N] of speed (m/s) and course (rad)."""
    return np.column_stack([speed * np.sin(course), speed * np.cos(course)])


# vertical 1σ that marks "no vertical velocity" in the in-motion start's kinematic fit
NO_VERTICAL_SIGMA_M_S = 1.0e3


def velocity_for_initialisation(speed_course, sigma):
    """(vel (M, 3), vel_sd (M, 3)) ENU for the start of a run only (stillness detection,
    in-motion fit, course heading; gmis.run_preparation): [s sin χ, s cos χ, 0] with the
    horizontal σ √(σ_s² + (s σ_χ)²) on both axes (the larger of the along/across σ) and
    NO_VERTICAL_SIGMA_M_S vertically — the fit takes no vertical information from it. Rows
    without a course (σ_χ NaN) get NO_VERTICAL_SIGMA_M_S on every axis."""
    s, chi = speed_course[:, 0], speed_course[:, 1]
    vel = np.column_stack([horizontal_velocity(s, chi), np.zeros(s.size)])
    h_sd = np.sqrt(sigma[:, 0] ** 2 + (s * sigma[:, 1]) ** 2)
    h_sd = np.where(np.isfinite(h_sd), h_sd, NO_VERTICAL_SIGMA_M_S)
    sd = np.column_stack([h_sd, h_sd, np.full(s.size, NO_VERTICAL_SIGMA_M_S)])
    return vel, sd
