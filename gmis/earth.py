"""WGS84 earth model in the earth-fixed ENU tangent frame of a declared origin (the
WGS-84 constants and geodetic ⇄ ECEF ⇄ ENU rotation are gnss.geodesy's, re-exported here).

gmis' navigation frame n is the ENU frame tangent to the ellipsoid at a fixed origin
(base station or first fix). It rotates with the earth but not with the vehicle, so the
transport rate ω_en^n of 001 eq. 4.1.39/4.1.40 is identically zero; in exchange the
gravity vector g^n(r) changes direction with position (≈ d/R rad at distance d), which
:func:`gravity_nav_into` evaluates exactly from normal gravity at the point.

A frame is packed as one float64 array (``NavFrame``, length 18) so numba code can take it:
``[lat0, lon0, h0, x0, y0, z0, C_e^n (9, row-major), ω_ie^n (3)]`` (rad, m, rad/s).
"""

import numpy as np
from numba import njit

# gmis geodesy is gnss.geodesy (imported, used here and re-exported)
from gnss.geodesy import (
    OMEGA_EARTH,
    WGS84_A,
    WGS84_B,
    WGS84_E2,
    WGS84_F,
    WGS84_GM,
    ecef_to_enu_matrix,
    ecef_to_geodetic,
    geodetic_to_ecef,
)

GAMMA_EQUATOR = 9.7803253359  # normal gravity at the equator (m/s^2)
SOMIGLIANA_K = 0.00193185265241
FRAME_SIZE = 18
FRAME_ORIGIN_ECEF, FRAME_C_EN = slice(3, 6), slice(6, 15)   # packed frame layout (doc)


@njit(cache=True)
def make_nav_frame(lat0, lon0, h0):
    """Pack the ENU tangent frame at origin (lat0, lon0 in rad, h0 in m)."""
    f = np.empty(FRAME_SIZE)
    f[0] = lat0
    f[1] = lon0
    f[2] = h0
    f[3:6] = geodetic_to_ecef(lat0, lon0, h0)
    f[6:15] = ecef_to_enu_matrix(lat0, lon0).ravel()
    f[15] = 0.0
    f[16] = OMEGA_EARTH * np.cos(lat0)
    f[17] = OMEGA_EARTH * np.sin(lat0)
    return f


@njit(cache=True)
def frame_rotation(frame):
    """C_e^n of a packed frame (3×3 copy)."""
    return frame[6:15].copy().reshape((3, 3))


@njit(cache=True)
def enu_to_ecef(frame, r_enu):
    """ENU coordinates (m) in the frame → ECEF (m)."""
    c = frame[6:15]
    out = np.empty(3)
    for i in range(3):
        out[i] = (frame[3 + i] + c[i] * r_enu[0] + c[3 + i] * r_enu[1]
                  + c[6 + i] * r_enu[2])
    return out


@njit(cache=True)
def ecef_to_enu(frame, r_ecef):
    """ECEF (m) → ENU coordinates (m) in the frame."""
    c = frame[6:15]
    out = np.empty(3)
    d0 = r_ecef[0] - frame[3]
    d1 = r_ecef[1] - frame[4]
    d2 = r_ecef[2] - frame[5]
    for i in range(3):
        out[i] = c[3 * i] * d0 + c[3 * i + 1] * d1 + c[3 * i + 2] * d2
    return out


@njit(cache=True)
def enu_to_geodetic(frame, r_enu):
    e = enu_to_ecef(frame, r_enu)
    return ecef_to_geodetic(e[0], e[1], e[2])


@njit(cache=True)
def geodetic_to_enu(frame, lat, lon, h):
    return ecef_to_enu(frame, geodetic_to_ecef(lat, lon, h))


@njit(cache=True)
def normal_gravity(lat, h):
    """Magnitude of WGS84 normal gravity (m/s²): Somigliana at the ellipsoid plus the
    second-order free-air correction in height h (m)."""
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_EQUATOR * (1.0 + SOMIGLIANA_K * s2) / np.sqrt(1.0 - WGS84_E2 * s2)
    m = OMEGA_EARTH ** 2 * WGS84_A ** 2 * WGS84_B / WGS84_GM
    return g0 * (1.0 - 2.0 / WGS84_A * (1.0 + WGS84_F + m - 2.0 * WGS84_F * s2) * h
                 + 3.0 / WGS84_A ** 2 * h * h)


@njit(cache=True)
def gravity_nav_into(frame, r_enu, g_out, dg_dr_out):
    """Normal gravity vector g^n (m/s², gravitation + centrifugal, along the ellipsoid
    normal at the point) in the origin ENU frame, and its gradient ∂g^n/∂r (1/s²).

    The gradient uses the point-mass form (|g|/ρ)(3 u uᵀ − I) with u the local up and
    ρ = a: it is ~3e-6 1/s² and enters only the IMU Jacobian, where it is negligible
    beside every other term but kept so the Jacobian is the derivative of the model.
    """
    lat, lon, h = enu_to_geodetic(frame, r_enu)
    g = normal_gravity(lat, h)
    up_e = np.empty(3)
    up_e[0] = np.cos(lat) * np.cos(lon)
    up_e[1] = np.cos(lat) * np.sin(lon)
    up_e[2] = np.sin(lat)
    c = frame[6:15]
    u = np.empty(3)
    for i in range(3):
        u[i] = c[3 * i] * up_e[0] + c[3 * i + 1] * up_e[1] + c[3 * i + 2] * up_e[2]
        g_out[i] = -g * u[i]
    k = g / (WGS84_A + h)
    for i in range(3):
        for j in range(3):
            dg_dr_out[i, j] = k * (3.0 * u[i] * u[j] - (1.0 if i == j else 0.0))


@njit(cache=True)
def earth_rate_nav(frame):
    """ω_ie^n (rad/s) in the origin ENU frame: constant, [0, Ω cos φ0, Ω sin φ0]."""
    return frame[15:18].copy()
