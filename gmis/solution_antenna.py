"""The solution at the primary antenna: ENU / geodetic position of the antenna
(r_ant = r_imu + C_b^n l, l = [antennas].primary_lever_arm_m in body RFU) for
solution.npz, and an RTKLIB-format solution.pos (gnss.pos_file.write_pos layout: calendar
GPST, lat/lon/h, Q, ns, sdn/sde/sdu, ratio) that gnss.pos_file.read_pos reads back.

Q of an output epoch is graded from the filter's own 1σ horizontal position (the larger of
E and N): ≤ 0.05 m → 1, ≤ 0.5 m → 2, else 5 (RTKLIB "single"); ns is that of the nearest
input GNSS epoch within 0.5 s (0 without one); ratio is written as 0. The σ written are
those of the IMU-centre position (the lever-arm attitude term is not added).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmis.enu_rows import enu_to_geodetic_rows
from gmis.frames import dcm_body_to_nav_array
from gnss.constants import SECONDS_PER_WEEK

Q_FIX_SIGMA_M = 0.05
Q_FLOAT_SIGMA_M = 0.5


def antenna_enu(enu, euler, lever_arm_rfu):
    """(N,3) antenna ENU (m) from the IMU-centre ENU (N,3) and [pitch, roll, heading] (N,3)."""
    return enu + dcm_body_to_nav_array(euler) @ np.asarray(lever_arm_rfu, float)


@dataclass
class _PosRows:
    t_gps: np.ndarray
    llh: np.ndarray
    q: np.ndarray
    n_sat: np.ndarray
    sigma_enu: np.ndarray
    ratio: np.ndarray


def quality(enu_sd):
    """RTKLIB-style Q per epoch from the 1σ ENU (module docstring)."""
    h = np.maximum(enu_sd[:, 0], enu_sd[:, 1])
    return np.where(h <= Q_FIX_SIGMA_M, 1, np.where(h <= Q_FLOAT_SIGMA_M, 2, 5))


def write_solution_pos(path, t_sow, gps_week, llh_ant, enu_sd, gnss=None,
                       header_lines=()) -> Path:
    """solution.pos at the antenna; t_sow (N,) GPS seconds of week of week gps_week."""
    from gnss.pos_file import write_pos

    return write_pos(path, _pos_solution(t_sow, gps_week, llh_ant, enu_sd, gnss),
                     header_lines)


def write_solution_pos_blocks(path, blocks, gps_week, gnss=None, header_lines=()) -> Path:
    """write_solution_pos of the rows of the (t_sow, llh_ant, enu_sd) blocks (an
    iterable, one block in memory at a time): every row's line depends on that row only,
    so the file is the one of the concatenated rows."""
    from gnss.pos_file import write_pos_blocks

    return write_pos_blocks(path, (_pos_solution(t, gps_week, llh, sd, gnss)
                                   for t, llh, sd in blocks), header_lines)


def _pos_solution(t_sow, gps_week, llh_ant, enu_sd, gnss):
    """The rows of solution.pos (module docstring) as gnss.pos_file.write_pos takes them."""
    n_sat = np.zeros(t_sow.size, dtype=np.int64)
    if gnss is not None and gnss.ns is not None and gnss.t.size:
        j = np.clip(np.searchsorted(gnss.t, t_sow), 1, gnss.t.size - 1)
        j = np.where(np.abs(gnss.t[j - 1] - t_sow) < np.abs(gnss.t[j] - t_sow), j - 1, j)
        near = np.abs(gnss.t[j] - t_sow) <= 0.5
        n_sat[near] = gnss.ns[j[near]]
    return _PosRows(t_gps=gps_week * SECONDS_PER_WEEK + t_sow, llh=llh_ant,
                    q=quality(enu_sd), n_sat=n_sat, sigma_enu=enu_sd,
                    ratio=np.zeros(t_sow.size))


def antenna_solution(prep, t, enu, euler):
    """(enu_ant, llh_ant) of the primary antenna for every epoch."""
    lever = np.asarray(prep.recipe.antennas.primary_lever_arm_m, float)
    enu_ant = antenna_enu(enu, euler, lever)
    return enu_ant, enu_to_geodetic_rows(prep.frame, np.ascontiguousarray(enu_ant))
