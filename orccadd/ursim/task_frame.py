"""Force mode's task frame, as URScript's `force_mode(task_frame, ..., type, ...)` transforms it:

1: the frame is turned so that its y-axis points from the TCP towards the frame's origin
   (its z-axis kept as close to the given one as that allows);
2: the frame as given;
3: the frame is turned about its z-axis so that its x-axis is the TCP's velocity projected onto
   the frame's x-y plane (kept as given while the TCP is at rest).

Only the orientation matters to the admittance (directions of the axes): `task_rotation`
returns the 3×3 rotation base ← task.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.state import FloatArray

EPS_M = 1e-6  # shorter vectors give no direction


def _unit(v: FloatArray) -> FloatArray | None:
    n = float(np.linalg.norm(v))
    return None if n < EPS_M else v / n


def task_rotation(
    frame_pose: FloatArray, frame_type: int, tcp_m: FloatArray, tcp_speed_m_s: FloatArray
) -> FloatArray:
    """The task frame's orientation in the base frame for the TCP at `tcp_m` moving at
    `tcp_speed_m_s` (both base frame)."""
    r: FloatArray = pin.exp3(np.asarray(frame_pose[3:6], dtype=np.float64))
    if frame_type == 1:
        y = _unit(np.asarray(frame_pose[0:3]) - tcp_m)
        if y is None:
            return r
        x = _unit(np.cross(y, r[:, 2]))
        if x is None:  # y along the frame's z: keep the frame's x as close as possible
            x = _unit(r[:, 0] - (r[:, 0] @ y) * y)
            if x is None:
                return r
        return np.column_stack((x, y, np.cross(x, y)))
    if frame_type == 3:
        z = r[:, 2]
        x = _unit(tcp_speed_m_s - (tcp_speed_m_s @ z) * z)
        if x is None:
            return r
        return np.column_stack((x, np.cross(z, x), z))
    return r
