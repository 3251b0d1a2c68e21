"""GPS − UTC leap-second count (s) at a UTC instant, for time stamps given in UTC.

GPS time runs without leap seconds from 1980-01-06 00:00 UTC; UTC has had a leap second
inserted at the end of each date below (IERS Bulletin C), so GPST − UTC = the number of
entries whose date lies at or before the instant. No leap second has been announced
after 2017-01-01 (IERS Bulletin C 70, 2025): later dates get 18 s.
"""

from __future__ import annotations

import calendar

import numpy as np

from gnss.constants import UNIX_TO_GPS_EPOCH_S

# UTC dates (year, month, day) from which GPST − UTC grows by one second
_STEPS = ((1981, 7, 1), (1982, 7, 1), (1983, 7, 1), (1985, 7, 1), (1988, 1, 1),
          (1990, 1, 1), (1991, 1, 1), (1992, 7, 1), (1993, 7, 1), (1994, 7, 1),
          (1996, 1, 1), (1997, 7, 1), (1999, 1, 1), (2006, 1, 1), (2009, 1, 1),
          (2012, 7, 1), (2015, 7, 1), (2017, 1, 1))
STEP_UNIX_S = np.array([calendar.timegm((y, m, d, 0, 0, 0)) for y, m, d in _STEPS], float)


def gps_minus_utc_s(unix_utc_s) -> np.ndarray:
    """GPST − UTC (s, integer-valued) at Unix time(s) unix_utc_s (s since 1970, UTC)."""
    return np.searchsorted(STEP_UNIX_S, np.asarray(unix_utc_s, float), side="right") \
        .astype(float)


def unix_utc_to_gps_s(unix_utc_s) -> np.ndarray:
    """Unix UTC seconds → seconds since the GPS epoch 1980-01-06 (GPST)."""
    t = np.asarray(unix_utc_s, float)
    return t - UNIX_TO_GPS_EPOCH_S + gps_minus_utc_s(t)
