"""WGS-84 geodesy: constants, geodetic ⇄ ECEF and the ECEF → ENU rotation.

Geodetic coordinates are (lat, lon, h) in rad, rad, m (ellipsoidal height); ECEF in m.
The scalar functions are numba-compiled (gmis' filter kernels call them); the ``*_rows``
forms apply them to (n, 3) arrays. All are pure (no state, no I/O).

    N(φ) = a / √(1 − e² sin²φ)
    x = (N + h) cos φ cos λ,  y = (N + h) cos φ sin λ,  z = (N (1 − e²) + h) sin φ
    C_e^n (ENU) rows: east = (−sin λ, cos λ, 0),
                      north = (−sin φ cos λ, −sin φ sin λ, cos φ),
                      up = (cos φ cos λ, cos φ sin λ, sin φ)
ECEF → geodetic iterates φ = atan2(z, p (1 − e² N/(N + h))), p = √(x² + y²), to < 1e-13 rad.
"""

import numpy as np
from numba import njit

WGS84_A = 6378137.0  # semi-major axis (m)
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_B = WGS84_A * (1.0 - WGS84_F)
WGS84_GM = 3.986004418e14  # m^3/s^2
OMEGA_EARTH = 7.2921151467e-5  # rad/s (IS-GPS-200 value)


@njit(cache=True)
def geodetic_to_ecef(lat, lon, h):
    """(lat, lon, h) in rad, rad, m → ECEF (3,) m."""
    sl, cl = np.sin(lat), np.cos(lat)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * sl * sl)
    out = np.empty(3)
    out[0] = (n + h) * cl * np.cos(lon)
    out[1] = (n + h) * cl * np.sin(lon)
    out[2] = (n * (1.0 - WGS84_E2) + h) * sl
    return out


@njit(cache=True)
def ecef_to_geodetic(x, y, z):
    """ECEF (m) → (lat, lon, h) in rad, rad, m; iterative, converged to < 1e-12 rad."""
    lon = np.arctan2(y, x)
    p = np.sqrt(x * x + y * y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    h = 0.0
    for _ in range(10):
        sl = np.sin(lat)
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * sl * sl)
        h = p / np.cos(lat) - n if abs(lat) < 1.3 else z / sl - n * (1.0 - WGS84_E2)
        new = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        if abs(new - lat) < 1e-13:
            lat = new
            break
        lat = new
    sl = np.sin(lat)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * sl * sl)
    h = p / np.cos(lat) - n if abs(lat) < 1.3 else z / sl - n * (1.0 - WGS84_E2)
    return lat, lon, h


@njit(cache=True)
def ecef_to_enu_matrix(lat, lon):
    """C_e^n (3, 3): rotation ECEF → ENU at (lat, lon) rad."""
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    c = np.empty((3, 3))
    c[0, 0] = -so
    c[0, 1] = co
    c[0, 2] = 0.0
    c[1, 0] = -sl * co
    c[1, 1] = -sl * so
    c[1, 2] = cl
    c[2, 0] = cl * co
    c[2, 1] = cl * so
    c[2, 2] = sl
    return c


@njit(cache=True)
def _geodetic_to_ecef_rows(llh):
    out = np.empty((llh.shape[0], 3))
    for i in range(llh.shape[0]):
        out[i] = geodetic_to_ecef(llh[i, 0], llh[i, 1], llh[i, 2])
    return out


@njit(cache=True)
def _ecef_to_geodetic_rows(xyz):
    out = np.empty((xyz.shape[0], 3))
    for i in range(xyz.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = ecef_to_geodetic(xyz[i, 0], xyz[i, 1], xyz[i, 2])
    return out


def geodetic_to_ecef_rows(llh) -> np.ndarray:
    """(n, 3) lat/lon/h (rad, rad, m) → (n, 3) ECEF m."""
    return _geodetic_to_ecef_rows(np.ascontiguousarray(np.reshape(llh, (-1, 3)), float))


def ecef_to_geodetic_rows(xyz) -> np.ndarray:
    """(n, 3) ECEF m → (n, 3) lat/lon/h (rad, rad, m), row by row as ecef_to_geodetic."""
    return _ecef_to_geodetic_rows(np.ascontiguousarray(np.reshape(xyz, (-1, 3)), float))


def ecef_to_enu_rows(xyz, origin_ecef) -> np.ndarray:
    """(n, 3) ECEF m → (n, 3) ENU m in the tangent frame at origin_ecef (3,) m."""
    origin = np.asarray(origin_ecef, float)
    lat, lon, _ = ecef_to_geodetic(origin[0], origin[1], origin[2])
    return (np.reshape(np.asarray(xyz, float), (-1, 3)) - origin) @ \
        ecef_to_enu_matrix(lat, lon).T


__all__ = [
    "OMEGA_EARTH",
    "WGS84_A",
    "WGS84_B",
    "WGS84_E2",
    "WGS84_F",
    "WGS84_GM",
    "ecef_to_enu_matrix",
    "ecef_to_enu_rows",
    "ecef_to_geodetic",
    "ecef_to_geodetic_rows",
    "geodetic_to_ecef",
    "geodetic_to_ecef_rows",
]
