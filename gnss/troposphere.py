"""Tropospheric delay: Saastamoinen zenith delays with a standard atmosphere, 1/cos z mapping.

Standard atmosphere (as in RTKLIB's tropmodel): P = 1013.25 (1 − 2.2557e-5 h)^5.2568 hPa,
T = 15 − 6.5e-3 h + 273.16 K, relative humidity 0.7, water-vapour pressure
e = 6.108 RH exp((17.15 T − 4684)/(T − 38.45)) hPa. Saastamoinen (1972):
  hydrostatic  T_h = 0.0022768 P / (1 − 0.00266 cos 2φ − 0.00028 h/km) / cos z
  wet          T_w = 0.002277 (1255/T + 0.05) e / cos z            (m)
with zenith angle z = π/2 − elevation. Heights below 0 are treated as 0; outside
[−100 m, 10 km] or for elevations ≤ 0 the delay is 0 (the model does not apply).
"""

import math

import numpy as np
from numba import njit

from gnss.geodesy import ecef_to_geodetic

STANDARD_HUMIDITY = 0.7


def saastamoinen_delay(lat, h, elevation, humidity: float = STANDARD_HUMIDITY):
    """Slant tropospheric delay (m) at geodetic latitude lat (rad), ellipsoidal height h (m)
    and satellite elevation (rad); arrays broadcast."""
    lat, h, el = np.broadcast_arrays(np.asarray(lat, float), np.asarray(h, float),
                                     np.asarray(elevation, float))
    hgt = np.clip(h, 0.0, 1e4)
    pres = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    cos_z = np.cos(np.pi / 2.0 - el)
    applies = (h >= -100.0) & (h <= 1e4) & (el > 0.0)
    cos_z = np.where(applies, cos_z, 1.0)
    dry = 0.0022768 * pres / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * hgt / 1e3) / cos_z
    wet = 0.002277 * (1255.0 / temp + 0.05) * e / cos_z
    return np.where(applies, dry + wet, 0.0)


@njit(cache=True)
def saastamoinen_delay_scalar(lat, h, elevation, humidity):
    """saastamoinen_delay for one satellite (m), numba-compiled for the per-epoch kernels
    (gnss.spp, gnss.rtk, gmis.tc_filter): the same formulas (module doc) evaluated with
    scalars; lat, elevation rad, h m, humidity 0-1."""
    if not (h >= -100.0 and h <= 1e4 and elevation > 0.0):
        return 0.0
    hgt = min(max(h, 0.0), 1e4)
    pres = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * math.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    cos_z = math.cos(math.pi / 2.0 - elevation)
    dry = 0.0022768 * pres / (1.0 - 0.00266 * math.cos(2.0 * lat) - 0.00028 * hgt / 1e3) \
        / cos_z
    wet = 0.002277 * (1255.0 / temp + 0.05) * e / cos_z
    return dry + wet


def slant_hydrostatic_delay(receiver_ecef, sat_ecef):
    """Hydrostatic Saastamoinen slant delay (m) from a receiver (3,) ECEF m to satellites
    (n, 3) ECEF m (humidity 0; elevation about the ellipsoid normal)."""
    receiver_ecef = np.asarray(receiver_ecef, float)
    lat, lon, h = ecef_to_geodetic(*receiver_ecef)
    los = np.asarray(sat_ecef, float) - receiver_ecef
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    elev = np.arcsin((los / np.linalg.norm(los, axis=1)[:, None]) @ up)
    return saastamoinen_delay(lat, h, elev, humidity=0.0)
