"""Row-wise coordinate conversions between geodetic (lat, lon rad; h m) and the ENU
tangent frame of a run (gmis.earth.make_nav_frame), for whole streams."""

import numpy as np
from numba import njit

from gmis.earth import ecef_to_enu, ecef_to_geodetic, enu_to_ecef, geodetic_to_ecef


@njit(cache=True)
def geodetic_to_enu_rows(frame, llh):
    """(K,3) [rad, rad, m] → (K,3) ENU m in the frame."""
    out = np.empty((llh.shape[0], 3))
    for k in range(llh.shape[0]):
        out[k] = ecef_to_enu(frame, geodetic_to_ecef(llh[k, 0], llh[k, 1], llh[k, 2]))
    return out


@njit(cache=True)
def enu_to_geodetic_rows(frame, enu):
    """(K,3) ENU m in the frame → (K,3) [rad, rad, m]."""
    out = np.empty((enu.shape[0], 3))
    for k in range(enu.shape[0]):
        e = enu_to_ecef(frame, enu[k])
        lat, lon, h = ecef_to_geodetic(e[0], e[1], e[2])
        out[k, 0] = lat
        out[k, 1] = lon
        out[k, 2] = h
    return out


__all__ = ["enu_to_geodetic_rows", "geodetic_to_enu_rows"]
