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


@njit(cache=True, inline="always")
def gravity_nav(frame, r_enu):
    """(g^n (m/s²), ∂g^n/∂r (1/s²)) at the ENU point r_enu (m) of the frame
    (gmis.earth.make_nav_frame): a 3-tuple and three row tuples (no allocation)."""
    c = frame[6:15]
    ex = frame[3] + c[0] * r_enu[0] + c[3] * r_enu[1] + c[6] * r_enu[2]
    ey = frame[4] + c[1] * r_enu[0] + c[4] * r_enu[1] + c[7] * r_enu[2]
    ez = frame[5] + c[2] * r_enu[0] + c[5] * r_enu[1] + c[8] * r_enu[2]
    lat, lon, h = ecef_to_geodetic(ex, ey, ez)
    g = normal_gravity(lat, h)
    u0e = math.cos(lat) * math.cos(lon)
    u1e = math.cos(lat) * math.sin(lon)
    u2e = math.sin(lat)
    u = (c[0] * u0e + c[1] * u1e + c[2] * u2e,
         c[3] * u0e + c[4] * u1e + c[5] * u2e,
         c[6] * u0e + c[7] * u1e + c[8] * u2e)
    k = g / (WGS84_A + h)
    dg = ((k * (3.0 * u[0] * u[0] - 1.0), k * (3.0 * u[0] * u[1] - 0.0),
           k * (3.0 * u[0] * u[2] - 0.0)),
          (k * (3.0 * u[1] * u[0] - 0.0), k * (3.0 * u[1] * u[1] - 1.0),
           k * (3.0 * u[1] * u[2] - 0.0)),
          (k * (3.0 * u[2] * u[0] - 0.0), k * (3.0 * u[2] * u[1] - 0.0),
           k * (3.0 * u[2] * u[2] - 1.0)))
    return (-g * u[0], -g * u[1], -g * u[2]), dg


@njit(cache=True)
def gravity_nav_into(frame, r_enu, g_out, dg_dr_out):
    """g^n (m/s²) into g_out (3,) and ∂g^n/∂r (1/s²) into dg_dr_out (3, 3) at the ENU
    point r_enu (m) of the frame (gmis.earth.make_nav_frame)."""
    g, dg = gravity_nav(frame, r_enu)
    for i in range(3):
        g_out[i] = g[i]
        for j in range(3):
            dg_dr_out[i, j] = dg[i][j]
