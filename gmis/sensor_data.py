"""The data objects the readers return (gmis.readers, gmis.readers_rtklib) and the engine
reads: IMU samples, GNSS solution, heading, reference trajectory, and the dataset that holds
them. SI units and radians; time in GPS seconds (of week, as the readers give it)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gmis.recipe import Recipe


@dataclass(frozen=True, eq=False)
class ImuData:
    """t (N,) s; gyro (N,3) rad/s and accel (N,3) m/s², both in body Right-Forward-Up."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    warnings: tuple[str, ...] = ()
    # (first, last) time of the whole file when the reader kept a [time] window only
    file_span: tuple[float, float] | None = None

    @property
    def z(self) -> np.ndarray:
        """(N, 6) [gyro, accel], C-contiguous: the readers' storage itself (gyro and
        accel are its column views, no copy) or, for other ImuData, a new array; for
        samples on disk (gmis.imu_spool.SpooledColumns) their ImuSpool."""
        spool = getattr(self.gyro, "spool", None)
        if spool is not None and getattr(self.accel, "spool", None) is spool:
            return spool
        base = self.gyro.base
        n = self.t.size
        if (base is not None and base is self.accel.base and base.shape == (n, 6)
                and base.dtype == np.float64 and base.flags.c_contiguous
                and self.gyro.ctypes.data == base.ctypes.data
                and self.accel.ctypes.data == base.ctypes.data + 3 * base.itemsize
                and self.gyro.shape == (n, 3) and self.accel.shape == (n, 3)):
            return base
        return np.hstack([self.gyro, self.accel])

    @property
    def rate_hz(self) -> float:
        return 1.0 / float(np.median(np.diff(self.t))) if self.t.size > 1 else math.nan


@dataclass(frozen=True, eq=False)
class GnssSolution:
    """Antenna positions: llh (M,3) [rad, rad, m]; pos_sigma (M,3) m in E,N,U;
    vel_enu / vel_sigma (M,3) m/s or None when the file has no velocity; speed_course /
    speed_course_sigma (M,2) [speed m/s, course rad] of a receiver without vertical velocity
    (gmis.speed_course) or None; a course σ of NaN marks a course not to be used."""

    t: np.ndarray
    llh: np.ndarray
    pos_sigma: np.ndarray
    vel_enu: np.ndarray | None = None
    vel_sigma: np.ndarray | None = None
    speed_course: np.ndarray | None = None
    speed_course_sigma: np.ndarray | None = None
    q: np.ndarray | None = None  # RTKLIB quality per epoch (.pos input), else None
    ns: np.ndarray | None = None  # satellites per epoch (.pos input), else None
    gps_week: int | None = None  # GPS week of t (.pos input), else None


@dataclass(frozen=True, eq=False)
class HeadingData:
    """Azimuth of the IMU forward axis, clockwise from north (rad), and its 1σ (rad)."""

    t: np.ndarray
    heading: np.ndarray
    sigma: np.ndarray


@dataclass(frozen=True, eq=False)
class ReferenceTrajectory:
    """Truth at the IMU centre: llh (K,3) [rad, rad, m], vel_enu (K,3) m/s,
    euler (K,3) [pitch, roll, heading] rad."""

    t: np.ndarray
    llh: np.ndarray
    vel_enu: np.ndarray
    euler: np.ndarray


@dataclass(frozen=True, eq=False)
class Dataset:
    recipe: Recipe
    imu: ImuData
    gnss: GnssSolution | None = None
    heading: HeadingData | None = None
    reference: ReferenceTrajectory | None = None
    warnings: tuple[str, ...] = field(default=())

    def origin_llh(self) -> tuple[float, float, float] | None:
        """ENU origin (rad, rad, m): the recipe's origin/base, else the first GNSS fix."""
        origin = self.recipe.origin_llh()
        if origin is None and self.gnss is not None and self.gnss.t.size:
            origin = tuple(float(x) for x in self.gnss.llh[0])
        return origin
