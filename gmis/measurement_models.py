"""Measurement models h(x) and Jacobians H = ∂h/∂x of the GMIKF.

IMU (001 eq. 4.1.39/4.1.40, 5.1.3-5.1.6): see :mod:`gmis.imu_model` for the model.
Loosely coupled GNSS (001 eq. 4.1.41-4.1.43), antenna lever arm L^b (m, body RFU):
    r_ant = r + C_b^n L                       (m, ENU)
    v_ant = C_b^n (v^b + ω×L)                 (m/s, ENU)
    ψ_gnss = ψ                                (rad, wrapped innovation)
Non-holonomic constraint (000 eq. 5.41-5.43 with identity boresight), constraint point at
l^b from the IMU (m, body RFU; e.g. the rear-axle centre):
    0 ≈ [(v^b + ω×l)_x, (v^b + ω×l)_z]         (m/s, lateral and vertical)

Every function writes its rows into a caller-provided stacked H (rows ``row0..``) so one
EKF update can carry all sensors of an epoch. Tested against central differences in
tests/test_measurement_models.py.
"""

import numpy as np
from numba import njit

from gmis.earth import gravity_nav_into
from gmis.frames import dcm_body_to_nav_into, dcm_body_to_nav_partials_into


@njit(cache=True)
def imu_model_and_jacobian_into(x, n_imu, frame, h_out, h_row0, jac, row0):
    """Predicted IMU outputs h (gyro rad/s, accel m/s²) into h_out[h_row0:h_row0+6] and
    their Jacobian into jac[row0:row0+6, :] (columns beyond the IMU states left 0).

    n_imu = 21 ignores scale factors (S = 0)."""
    c = np.empty((3, 3))
    dcm_body_to_nav_into(x[9], x[10], x[11], c)
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_partials_into(x[9], x[10], x[11], dc[0], dc[1], dc[2])
    g = np.empty(3)
    dg = np.empty((3, 3))
    gravity_nav_into(frame, x[0:3], g, dg)
    w_ie = frame[15:18]
    v = x[3:6]
    # v^n, Coriolis term k = 2 ω_ie × v^n and its partials
    vn = c @ v
    kx = np.empty((3, 3))  # [2ω_ie ×]
    kx[0, 0] = 0.0
    kx[0, 1] = -2.0 * w_ie[2]
    kx[0, 2] = 2.0 * w_ie[1]
    kx[1, 0] = 2.0 * w_ie[2]
    kx[1, 1] = 0.0
    kx[1, 2] = -2.0 * w_ie[0]
    kx[2, 0] = -2.0 * w_ie[1]
    kx[2, 1] = 2.0 * w_ie[0]
    kx[2, 2] = 0.0
    cor = kx @ vn
    spec = cor - g                      # nav-frame part of 4.1.40
    for r in range(6):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        sw = x[21 + i] if n_imu >= 27 else 0.0
        sa = x[24 + i] if n_imu >= 27 else 0.0
        wie_b = c[0, i] * w_ie[0] + c[1, i] * w_ie[1] + c[2, i] * w_ie[2]
        spec_b = c[0, i] * spec[0] + c[1, i] * spec[1] + c[2, i] * spec[2]
        gyro_core = x[12 + i] + wie_b
        acc_core = x[6 + i] + spec_b
        h_out[h_row0 + i] = (1.0 + sw) * gyro_core + x[15 + i]
        h_out[h_row0 + 3 + i] = (1.0 + sa) * acc_core + x[18 + i]
        rg = row0 + i
        ra = row0 + 3 + i
        # gyro
        jac[rg, 12 + i] = 1.0 + sw
        jac[rg, 15 + i] = 1.0
        if n_imu >= 27:
            jac[rg, 21 + i] = gyro_core
            jac[ra, 24 + i] = acc_core
        # accel
        jac[ra, 6 + i] = 1.0 + sa
        jac[ra, 18 + i] = 1.0
        for m in range(3):
            # attitude: ∂(C^T u)_i/∂θ_m = Σ_l dC_m[l, i] u_l (+ C^T kx dC_m v for Coriolis)
            dcv = dc[m] @ v
            dkv = kx @ dcv
            jac[rg, 9 + m] = (1.0 + sw) * (dc[m][0, i] * w_ie[0] + dc[m][1, i] * w_ie[1]
                                           + dc[m][2, i] * w_ie[2])
            jac[ra, 9 + m] = (1.0 + sa) * (dc[m][0, i] * spec[0] + dc[m][1, i] * spec[1]
                                           + dc[m][2, i] * spec[2]
                                           + c[0, i] * dkv[0] + c[1, i] * dkv[1]
                                           + c[2, i] * dkv[2])
        for col in range(3):
            # velocity: C^T kx C;  position: −C^T ∂g/∂r
            kc0 = kx[0, 0] * c[0, col] + kx[0, 1] * c[1, col] + kx[0, 2] * c[2, col]
            kc1 = kx[1, 0] * c[0, col] + kx[1, 1] * c[1, col] + kx[1, 2] * c[2, col]
            kc2 = kx[2, 0] * c[0, col] + kx[2, 1] * c[1, col] + kx[2, 2] * c[2, col]
            jac[ra, 3 + col] = (1.0 + sa) * (c[0, i] * kc0 + c[1, i] * kc1 + c[2, i] * kc2)
            jac[ra, col] = -(1.0 + sa) * (c[0, i] * dg[0, col] + c[1, i] * dg[1, col]
                                          + c[2, i] * dg[2, col])


@njit(cache=True)
def gnss_position_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """r_ant = r + C_b^n L (eq. 4.1.41) and its Jacobian rows (3 rows)."""
    c = np.empty((3, 3))
    dcm_body_to_nav_into(x[9], x[10], x[11], c)
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_partials_into(x[9], x[10], x[11], dc[0], dc[1], dc[2])
    for r in range(3):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        h_out[h_row0 + i] = x[i] + c[i, 0] * lever_arm[0] + c[i, 1] * lever_arm[1] \
            + c[i, 2] * lever_arm[2]
        jac[row0 + i, i] = 1.0
        for m in range(3):
            jac[row0 + i, 9 + m] = (dc[m][i, 0] * lever_arm[0] + dc[m][i, 1] * lever_arm[1]
                                    + dc[m][i, 2] * lever_arm[2])


@njit(cache=True)
def gnss_velocity_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """v_ant = C_b^n (v^b + ω×L) (eq. 4.1.42) and its Jacobian rows (3 rows)."""
    c = np.empty((3, 3))
    dcm_body_to_nav_into(x[9], x[10], x[11], c)
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_partials_into(x[9], x[10], x[11], dc[0], dc[1], dc[2])
    om = x[12:15]
    u = np.empty(3)
    u[0] = x[3] + om[1] * lever_arm[2] - om[2] * lever_arm[1]
    u[1] = x[4] + om[2] * lever_arm[0] - om[0] * lever_arm[2]
    u[2] = x[5] + om[0] * lever_arm[1] - om[1] * lever_arm[0]
    # ∂(ω×L)/∂ω = −[L×]
    lx = np.empty((3, 3))
    lx[0, 0] = 0.0
    lx[0, 1] = lever_arm[2]
    lx[0, 2] = -lever_arm[1]
    lx[1, 0] = -lever_arm[2]
    lx[1, 1] = 0.0
    lx[1, 2] = lever_arm[0]
    lx[2, 0] = lever_arm[1]
    lx[2, 1] = -lever_arm[0]
    lx[2, 2] = 0.0
    for r in range(3):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        h_out[h_row0 + i] = c[i, 0] * u[0] + c[i, 1] * u[1] + c[i, 2] * u[2]
        for k in range(3):
            jac[row0 + i, 3 + k] = c[i, k]
            jac[row0 + i, 12 + k] = c[i, 0] * lx[0, k] + c[i, 1] * lx[1, k] + c[i, 2] * lx[2, k]
        for m in range(3):
            jac[row0 + i, 9 + m] = dc[m][i, 0] * u[0] + dc[m][i, 1] * u[1] + dc[m][i, 2] * u[2]


@njit(cache=True)
def heading_model_and_jacobian_into(x, h_out, h_row0, jac, row0):
    """ψ_gnss = ψ (eq. 4.1.43); the innovation must be wrapped to [-π, π)."""
    for col in range(jac.shape[1]):
        jac[row0, col] = 0.0
    h_out[h_row0] = x[11]
    jac[row0, 11] = 1.0


@njit(cache=True)
def nonholonomic_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """Lateral and vertical body velocity of the constraint point, u = v^b + ω×l (000 eq.
    5.41; v^b and ω are GMIKF states, so H is linear: ∂u/∂v = I, ∂u/∂ω = −[l×])."""
    lx, ly, lz = lever_arm[0], lever_arm[1], lever_arm[2]
    for r in range(2):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    # (ω×l)_x = ω_y l_z − ω_z l_y ;  (ω×l)_z = ω_x l_y − ω_y l_x
    h_out[h_row0] = x[3] + x[13] * lz - x[14] * ly
    h_out[h_row0 + 1] = x[5] + x[12] * ly - x[13] * lx
    jac[row0, 3] = 1.0
    jac[row0, 13] = lz
    jac[row0, 14] = -ly
    jac[row0 + 1, 5] = 1.0
    jac[row0 + 1, 12] = ly
    jac[row0 + 1, 13] = -lx
