"""Normal gravity in the origin ENU frame, the one numba gravity model of the filters'
kernels (gmis.imu_model, gmis.measurement_models, gmis.errins).

g^n(r) = −|γ(φ, h)| u(r): WGS-84 normal gravity magnitude (Somigliana + second-order
free-air, :func:`gmis.earth.normal_gravity`) along the ellipsoid normal u at the point,
rotated into the origin ENU frame; gradient ∂g^n/∂r ≈ (|g|/(a + h)) (3 u uᵀ − I) (point
mass), ~3e-6 1/s², kept so the IMU Jacobian is the derivative of the model. Writes into
caller buffers: no heap allocation.
"""

import math

from numba import njit

from gmis.earth import WGS84_A, ecef_to_geodetic, normal_gravity


@njit(cache=True)
def gravity_nav_into(frame, r_enu, g_out, dg_dr_out):
    """g^n (m/s²) into g_out (3,) and ∂g^n/∂r (1/s²) into dg_dr_out (3, 3) at the ENU
    point r_enu (m) of the frame (gmis.earth.make_nav_frame)."""
    c = frame[6:15]
    ex = frame[3] + c[0] * r_enu[0] + c[3] * r_enu[1] + c[6] * r_enu[2]
    ey = frame[4] + c[1] * r_enu[0] + c[4] * r_enu[1] + c[7] * r_enu[2]
    ez = frame[5] + c[2] * r_enu[0] + c[5] * r_enu[1] + c[8] * r_enu[2]
    lat, lon, h = ecef_to_geodetic(ex, ey, ez)
    g = normal_gravity(lat, h)
    u0e = math.cos(lat) * math.cos(lon)
    u1e = math.cos(lat) * math.sin(lon)
    u2e = math.sin(lat)
    u0 = c[0] * u0e + c[1] * u1e + c[2] * u2e
    u1 = c[3] * u0e + c[4] * u1e + c[5] * u2e
    u2 = c[6] * u0e + c[7] * u1e + c[8] * u2e
    g_out[0] = -g * u0
    g_out[1] = -g * u1
    g_out[2] = -g * u2
    k = g / (WGS84_A + h)
    for i in range(3):
        ui = u0 if i == 0 else (u1 if i == 1 else u2)
        for j in range(3):
            uj = u0 if j == 0 else (u1 if j == 1 else u2)
            dg_dr_out[i, j] = k * (3.0 * ui * uj - (1.0 if i == j else 0.0))
