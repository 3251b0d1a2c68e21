"""IMU mounting: sensor axes → gmis body frame (Right-Forward-Up, gmis.frames).

A mounting is given as roll/pitch/yaw angles (deg) of the sensor in a body frame, in the
RTKLIB / KF-GINS convention: C_s^b = R_z(yaw) R_y(pitch) R_x(roll) (a vector's components
in sensor axes → body axes, v^b = C_s^b v^s). A misalignment given "after" the mounting is
applied on top of it: C = C_mis C_mount. When those angles refer to Forward-Right-Down body
axes (body_frame = "FRD"), the result is re-expressed in RFU with
T_FRD^RFU = [[0,1,0],[1,0,0],[0,0,-1]] (right = FRD y, forward = FRD x, up = −FRD z).
The signed axis permutation [imu].axes (gmis.recipe.axes_matrix) is applied first:
v^RFU = T C_mis C_mount M_axes v^sensor, with T = I for RFU angles.
"""

from __future__ import annotations

import numpy as np

FRD_TO_RFU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def rpy_dcm(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """R_z(yaw) R_y(pitch) R_x(roll) (angles in degrees): sensor → body components."""
    r, p, y = np.radians([roll_deg, pitch_deg, yaw_deg])
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def frame_to_rfu(body_frame: str) -> np.ndarray:
    """T with v^RFU = T v^frame for body_frame "RFU" or "FRD"."""
    return np.eye(3) if body_frame == "RFU" else FRD_TO_RFU.copy()


def mounting_matrix(axes_matrix: np.ndarray, mounting_rpy_deg=(0.0, 0.0, 0.0),
                    misalignment_rpy_deg=(0.0, 0.0, 0.0), body_frame: str = "RFU"
                    ) -> np.ndarray:
    """C (3×3, orthonormal, det +1) with v^RFU = C v^sensor (see module docstring)."""
    c = rpy_dcm(*misalignment_rpy_deg) @ rpy_dcm(*mounting_rpy_deg) @ axes_matrix
    return frame_to_rfu(body_frame) @ c
