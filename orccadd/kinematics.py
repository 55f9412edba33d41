"""The tool's kinematics from the model: its pose, its frame Jacobian and the task error.

Conventions, the same in every Cartesian module:
- a pose is a position (m, base frame) and an orientation as a unit quaternion (x, y, z, w),
  the order of Pinocchio's `coeffs()` and of ROS's geometry_msgs/Pose;
- a twist or an error is six numbers, linear (m/s or m) then angular (rad/s or rad), on the
  base frame's axes at the tool's point (Pinocchio's LOCAL_WORLD_ALIGNED);
- the orientation error of R toward R_des is log3(R_des·Rᵀ): the rotation vector (axis times
  angle, base axes) that turns R into R_des.

`ToolKinematics` owns its Pinocchio workspace (one per module: the model/workspace split of
orccadd/model.py) and preallocated arrays: the tick allocates no buffer of its own.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from orccadd.config.robot import WorkspaceConfig
from orccadd.model import RobotModel

FloatArray = npt.NDArray[np.float64]
WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class ToolKinematics:
    """Forward kinematics and the Jacobian of the robot's tool frame (`[tool]` of the config)."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self._m = model.model
        self._d = model.new_data()
        self.frame_id = model.tool_frame_id
        self.q: FloatArray = np.zeros(model.dof)  # the configuration last computed
        self.jacobian: FloatArray = np.zeros((6, model.dof))

    def pose(self, q: FloatArray | list[float]) -> pin.SE3:
        """The tool's placement in the base frame at `q` (the workspace's own SE3: copy to keep)."""
        self.q[:] = q
        pin.forwardKinematics(self._m, self._d, self.q)
        return pin.updateFramePlacement(self._m, self._d, self.frame_id)

    def pose_and_jacobian(self, q: FloatArray | list[float]) -> pin.SE3:
        """The tool's placement at `q`, and its Jacobian into `self.jacobian` (6×n, linear then
        angular rows, base axes at the tool's point)."""
        self.q[:] = q
        self.jacobian[:] = pin.computeFrameJacobian(self._m, self._d, self.q, self.frame_id, WORLD_ALIGNED)
        return pin.updateFramePlacement(self._m, self._d, self.frame_id)


def quaternion_of(rotation: FloatArray) -> list[float]:
    """A rotation matrix as a unit quaternion (x, y, z, w), w >= 0."""
    x, y, z, w = pin.Quaternion(rotation).coeffs().tolist()
    return [-x, -y, -z, -w] if w < 0.0 else [x, y, z, w]


def rotation_of(quaternion: FloatArray | list[float]) -> FloatArray:
    """A quaternion (x, y, z, w), normalised, as a rotation matrix."""
    q = pin.Quaternion(np.asarray(quaternion, dtype=np.float64))
    q.normalize()
    return np.asarray(q.toRotationMatrix())


def pose_error(
    position_m: FloatArray, rotation: FloatArray, position_des_m: FloatArray, rotation_des: FloatArray
) -> FloatArray:
    """The task error toward the desired pose: (p_des − p, log3(R_des·Rᵀ)), base axes."""
    e = np.empty(6)
    e[:3] = position_des_m - position_m
    e[3:] = pin.log3(rotation_des @ rotation.T)
    return e


def rotation_error(q: list[float], q_des: list[float]) -> list[float]:
    """log3(R_des·Rᵀ) from the two unit quaternions (x, y, z, w), on plain floats: the rotation
    vector (base axes) that turns q into q_des, as `pose_error` computes it from matrices, at a
    fraction of the cost (no array, no Pinocchio object). Inputs are normalised here."""
    x1, y1, z1, w1 = _unit(q_des)
    x2, y2, z2, w2 = _unit(q)
    x2, y2, z2 = -x2, -y2, -z2  # q's conjugate: q_des ⊗ q*
    x = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    y = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    z = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    w = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    if w < 0.0:  # the shorter way round
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(s, w) / s if s > 1e-12 else 2.0
    return [k * x, k * y, k * z]


def task_error(pose: pin.SE3, position_des_m: list[float], orientation_des: list[float]) -> list[float]:
    """`pose_error` toward a desired pose given as floats (a module's inputs): six floats."""
    px, py, pz = pose.translation.tolist()
    dx, dy, dz = position_des_m
    return [dx - px, dy - py, dz - pz, *rotation_error(quaternion_of(pose.rotation), orientation_des)]


def rotate_back(q: list[float], v: list[float]) -> list[float]:
    """Rᵀ·v for the unit quaternion q (x, y, z, w) of R, on plain floats."""
    x, y, z, w = _unit(q)
    x, y, z = -x, -y, -z  # the conjugate rotates back
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return [vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz, vz + w * tz + x * ty - y * tx]


def _unit(q: list[float]) -> tuple[float, float, float, float]:
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return (x / n, y / n, z / n, w / n) if n > 0.0 else (0.0, 0.0, 0.0, 1.0)


def angle_between(rotation_a: FloatArray, rotation_b: FloatArray) -> float:
    """The angle (rad, in [0, π]) of the rotation that turns `rotation_a` into `rotation_b`."""
    c = 0.5 * (float(np.trace(rotation_b @ rotation_a.T)) - 1.0)
    return math.acos(max(-1.0, min(1.0, c)))


def manipulability(jacobian: FloatArray) -> float:
    """Yoshikawa's measure sqrt(det(J·Jᵀ)) (0 at a singularity; units mixed: a nearness
    indicator compared with its own value at a reference pose, not a physical quantity)."""
    d = float(np.linalg.det(jacobian @ jacobian.T))
    return math.sqrt(d) if d > 0.0 else 0.0


def damped_pseudo_inverse(jacobian: FloatArray, damping: float) -> FloatArray:
    """J⁺ = Jᵀ(J·Jᵀ + damping²·I)⁻¹: the least-squares inverse, damped near singularities."""
    jjt = jacobian @ jacobian.T
    jjt[np.diag_indices_from(jjt)] += damping * damping
    return np.asarray(jacobian.T @ np.linalg.inv(jjt))


def clip_norm(v: FloatArray, limit: float) -> FloatArray:
    """`v` scaled down to a norm of at most `limit` (its direction kept)."""
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit else v


def smallest_singular_value(jacobian: FloatArray) -> float:
    """σ_min of J (rows: six task directions)."""
    return float(np.linalg.svd(jacobian, compute_uv=False)[-1])


class ToolWorkspace:
    """The robot config's `[workspace]` on the tool's point: where a configuration puts it, and
    whether that is inside (a box and/or a sphere, base frame), by a margin."""

    def __init__(self, model: RobotModel) -> None:
        self._kin = ToolKinematics(model)
        self.config: WorkspaceConfig = model.workspace
        w = self.config
        self._lo = list(w.box_min_m)
        self._hi = list(w.box_max_m)
        self._centre = list(w.sphere_center_m)
        self._r2 = w.sphere_radius_m**2
        self.point_m: list[float] = [0.0, 0.0, 0.0]  # the tool's point last computed

    @staticmethod
    def of(model: RobotModel) -> ToolWorkspace | None:
        """The guard of `model`'s workspace, or None when the config has none."""
        return ToolWorkspace(model) if model.workspace.given else None

    def excess_m(self, q: FloatArray | list[float]) -> float:
        """How far outside the workspace the tool is at `q` (m; 0 inside; inf if not finite).
        Tick-safe: one forward kinematics and a few operations on floats."""
        self.point_m = p = self._kin.pose(q).translation.tolist()
        if not all(map(math.isfinite, p)):
            return math.inf
        excess = 0.0
        if self._lo:
            out = [max(lo - v, v - hi, 0.0) for v, lo, hi in zip(p, self._lo, self._hi, strict=True)]
            excess = math.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)
        if self._r2 > 0.0:
            c = self._centre
            d = math.sqrt((p[0] - c[0]) ** 2 + (p[1] - c[1]) ** 2 + (p[2] - c[2]) ** 2)
            excess = max(excess, d - math.sqrt(self._r2))
        return excess

    def describe_outside(self) -> str:
        """Where the tool was found, and the workspace it left (the words of the type 3)."""
        x, y, z = self.point_m
        w, parts = self.config, []
        if w.box_min_m:
            parts.append(f"box {list(w.box_min_m)}..{list(w.box_max_m)} m")
        if w.sphere_radius_m > 0.0:
            parts.append(f"sphere of {w.sphere_radius_m:g} m about {list(w.sphere_center_m)} m")
        return f"tool at ({x:.4f}, {y:.4f}, {z:.4f}) m outside the workspace ({' and '.join(parts)})"
