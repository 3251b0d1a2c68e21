"""IMU measurement model of the GMIKF (001 eq. 4.1.39, 4.1.40), shared by the filter and
the simulator so both hold the same physics.

In gmis' earth-fixed ENU tangent frame (see :mod:`gmis.earth`) the transport rate is zero
and gravity is the position-dependent normal gravity vector, so

    ω_imu = (I + S_ω)(ω_nb^b + C_n^b ω_ie^n) + b_ω                       (4.1.39)
    f_imu = (I + S_a)(a_nb^b + C_n^b (2 ω_ie^n × v^n) − C_n^b g^n(r)) + b_a  (4.1.40)

with v^n = C_b^n v^b and S diagonal. Units: rad/s, m/s².
"""

import numpy as np
from numba import njit

from gmis.frames import dcm_body_to_nav_into
from gmis.gravity import gravity_nav_into


@njit(cache=True)
def imu_measurement_into(r, v_b, a_b, theta, omega_b, b_w, b_a, s_w, s_a, frame, out):
    """Predicted gyro (out[0:3], rad/s) and accelerometer (out[3:6], m/s²) outputs."""
    c_bn = np.empty((3, 3))
    dcm_body_to_nav_into(theta[0], theta[1], theta[2], c_bn)
    g = np.empty(3)
    dg = np.empty((3, 3))
    gravity_nav_into(frame, r, g, dg)
    w_ie = frame[15:18]
    v_n = c_bn @ v_b
    cor = np.empty(3)
    cor[0] = 2.0 * (w_ie[1] * v_n[2] - w_ie[2] * v_n[1])
    cor[1] = 2.0 * (w_ie[2] * v_n[0] - w_ie[0] * v_n[2])
    cor[2] = 2.0 * (w_ie[0] * v_n[1] - w_ie[1] * v_n[0])
    for i in range(3):
        # C_n^b = (C_b^n)^T: column i of C_b^n
        wie_b = c_bn[0, i] * w_ie[0] + c_bn[1, i] * w_ie[1] + c_bn[2, i] * w_ie[2]
        cor_b = c_bn[0, i] * cor[0] + c_bn[1, i] * cor[1] + c_bn[2, i] * cor[2]
        g_b = c_bn[0, i] * g[0] + c_bn[1, i] * g[1] + c_bn[2, i] * g[2]
        out[i] = (1.0 + s_w[i]) * (omega_b[i] + wie_b) + b_w[i]
        out[3 + i] = (1.0 + s_a[i]) * (a_b[i] + cor_b - g_b) + b_a[i]


@njit(cache=True)
def imu_measurement(r, v_b, a_b, theta, omega_b, b_w, b_a, s_w, s_a, frame):
    out = np.empty(6)
    imu_measurement_into(r, v_b, a_b, theta, omega_b, b_w, b_a, s_w, s_a, frame, out)
    return out
