"""Initialisation of the GMIKF state (001 §4.3.1-style static alignment).

Pitch and roll from the mean specific force over a static window: at rest
f^b = C_n^b (−g^n) = |g| [−sin γ cos p, sin p, cos γ cos p]ᵀ (eq. 2.2.4 third row), so
p = asin(f_y/|f|), γ = atan2(−f_x, f_z). The gyro bias starts at the window's mean rate
minus the earth rate seen in the body frame. Heading and position come from the first
heading / GNSS fixes (the position fix is moved from the antenna to the IMU centre).
"""

from dataclasses import dataclass

import numpy as np

from gmis.errors import GmisInputError
from gmis.frames import dcm_body_to_nav


@dataclass(frozen=True)
class StaticAlignment:
    pitch: float             # rad
    roll: float              # rad
    gyro_bias: np.ndarray    # (3,) rad/s
    n_samples: int
    accel_std: np.ndarray    # (3,) m/s², spread inside the window (motion check)
    gyro_std: np.ndarray     # (3,) rad/s


def static_alignment(t, gyro, accel, t_start, duration_s, earth_rate_nav, heading=0.0):
    """Level the IMU over [t_start, t_start + duration_s] (s). gyro rad/s, accel m/s²."""
    sel = (t >= t_start) & (t < t_start + duration_s)
    if sel.sum() < 10:
        raise GmisInputError(f"static alignment window of {duration_s} s holds "
                             f"{int(sel.sum())} IMU samples; need at least 10",
                             "filter.static_alignment_s")
    f = accel[sel].mean(axis=0)
    pitch = float(np.arcsin(np.clip(f[1] / np.linalg.norm(f), -1.0, 1.0)))
    roll = float(np.arctan2(-f[0], f[2]))
    c_bn = dcm_body_to_nav(pitch, roll, heading)
    bias = gyro[sel].mean(axis=0) - c_bn.T @ earth_rate_nav
    return StaticAlignment(pitch, roll, bias, int(sel.sum()), accel[sel].std(axis=0),
                           gyro[sel].std(axis=0))
