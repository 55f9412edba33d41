"""Task functions in Cartesian space: the tool's pose, its error, its straight-line motion.

The tool is the robot config's `[tool]` (a URDF frame and an offset, orccadd/model.py); poses,
twists and errors follow orccadd/kinematics.py's conventions (position in m and a quaternion
x, y, z, w; six-vectors linear then angular, base axes at the tool's point). The joint
commands come from `resolved_rate` (orccadd/modules/kinematic_control.py).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin
from ruckig import InputParameter, OutputParameter, Result, Ruckig, Synchronization

from orccadd.errors import ParameterError
from orccadd.kinematics import (
    ToolKinematics,
    angle_between,
    manipulability,
    quaternion_of,
    rotate_back,
    rotation_error,
)
from orccadd.model import RobotModel
from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.modules.trajectory import ruckig_step
from orccadd.state import JointState

TWIST_UNIT = "m/s|rad/s"
ERROR_UNIT = "m|rad"
IDENTITY_QUATERNION = [0.0, 0.0, 0.0, 1.0]


@register("tool_pose")
class ToolPose(KernelModule):
    """The measured tool's pose, twist (J·dq) and manipulability sqrt(det(J·Jᵀ)), from q, dq."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.add_input("q", (n,), "rad")
        self.add_input("dq", (n,), "rad/s")
        self.add_output("position_m", (3,), "m")
        self.add_output("orientation", (4,), "1")
        self.add_output("twist", (6,), TWIST_UNIT)
        self.add_output("manipulability", (), "1")
        self._kin = ToolKinematics(ctx.model)
        self._dq = np.zeros(n)

    def kernel(self) -> Kernel:
        kin, dqa = self._kin, self._dq

        def tool_pose(
            t_s: float, q: list[float], dq: list[float]
        ) -> tuple[list[float], list[float], list[float], float]:
            pose = kin.pose_and_jacobian(q)
            dqa[:] = dq
            twist = (kin.jacobian @ dqa).tolist()
            return (
                pose.translation.tolist(),
                quaternion_of(pose.rotation),
                twist,
                manipulability(kin.jacobian),
            )

        return tool_pose


@register("pose_error")
class PoseError(KernelModule):
    """The task error of a pose toward a desired one: (p_des − p, log3(R_des·Rᵀ)) on the base
    axes (`error`) and on the tool's (`error_tool`, Rᵀ times it), the distance (m) and the angle
    (rad) between them."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("position_m", (3,), "m")
        self.add_input("orientation", (4,), "1")
        self.add_input("position_des_m", (3,), "m")
        self.add_input("orientation_des", (4,), "1")
        self.add_output("error", (6,), ERROR_UNIT)
        self.add_output("error_tool", (6,), ERROR_UNIT)
        self.add_output("distance_m", (), "m")
        self.add_output("angle_rad", (), "rad")

    def kernel(self) -> Kernel:
        def error(
            t_s: float, p: list[float], o: list[float], p_des: list[float], o_des: list[float]
        ) -> tuple[list[float], list[float], float, float]:
            e_lin = [a - b for a, b in zip(p_des, p, strict=True)]
            e_rot = rotation_error(o, o_des)  # log3(R_des·Rᵀ), on floats (kinematics.py)
            tool = rotate_back(o, e_lin) + rotate_back(o, e_rot)
            dist, angle = math.sqrt(sum(v * v for v in e_lin)), math.sqrt(sum(v * v for v in e_rot))
            return (e_lin + e_rot, tool, dist, angle)

        return error


Outputs = tuple[list[float], list[float], list[float], list[float], list[float], bool, bool]


class _Line(KernelModule):
    """Base of the straight-line motions: from the tool's pose when the task starts to a goal
    pose (`_goal`), the position along the line and the orientation along the shortest rotation
    (slerp), each path's progress time-optimal and jerk-limited (Ruckig, two axes: the distance
    in m and the angle in rad, in phase so that both end together) within the tool's limits
    (`[tool]`) times `speed_scale`. Outputs the desired pose and twist, the goal, `finished`,
    and `outside_workspace` when the goal is out of the config's `[workspace]` (then the motion
    does not start: the desired pose holds the start; wire it to a type 2 or 3 exception)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_output("position_des_m", (3,), "m")
        self.add_output("orientation_des", (4,), "1")
        self.add_output("twist_des", (6,), TWIST_UNIT)
        self.add_output("position_goal_m", (3,), "m")
        self.add_output("orientation_goal", (4,), "1")
        self.add_output("finished", (), "bool", dtype=np.bool_)
        self.add_output("outside_workspace", (), "bool", dtype=np.bool_)
        self.speed_scale = self.add_parameter("speed_scale", 1.0, bounds=(0.01, 1.0), unit="1", tunable=True)
        self._kin = ToolKinematics(ctx.model)
        self._otg = Ruckig(2, ctx.period_s)
        self._inp = InputParameter(2)
        self._out = OutputParameter(2)
        self._inp.synchronization = Synchronization.Phase
        self._p0 = np.zeros(3)
        self._r0 = np.eye(3)
        self._direction = np.zeros(3)  # unit vector of the line (zeros: no distance to go)
        self._axis = np.zeros(3)  # unit rotation axis, base axes (zeros: no angle to turn)
        self._done = True
        zeros3 = [0.0] * 3
        self._outs: Outputs = (
            zeros3,
            IDENTITY_QUATERNION,
            [0.0] * 6,
            zeros3,
            IDENTITY_QUATERNION,
            True,
            False,
        )
        self._apply_limits()

    def _goal(self, p0: np.ndarray, r0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The goal's position and rotation, given the start's."""
        raise NotImplementedError

    def _apply_limits(self) -> None:
        tool, s = self.ctx.model.tool, float(self.speed_scale.value)
        self._inp.max_velocity = [tool.max_linear_velocity_m_s * s, tool.max_angular_velocity_rad_s * s]
        self._inp.max_acceleration = [
            tool.max_linear_acceleration_m_s2 * s,
            tool.max_angular_acceleration_rad_s2 * s,
        ]
        self._inp.max_jerk = [tool.max_linear_jerk_m_s3 * s, tool.max_angular_jerk_rad_s3 * s]

    def on_parameter_change(self, name: str) -> None:
        if name == "speed_scale":
            self._apply_limits()

    def start(self, state: JointState) -> None:
        pose = self._kin.pose(state.q_rad)
        p0, r0 = pose.translation.copy(), pose.rotation.copy()
        p1, r1 = self._goal(p0, r0)
        start = (p0.tolist(), quaternion_of(r0), [0.0] * 6)
        outside = not inside_workspace(self.ctx.model, p1)
        self._p0, self._r0 = p0, r0
        distance = float(np.linalg.norm(p1 - p0))
        rot = pin.log3(r1 @ r0.T)
        angle = float(np.linalg.norm(rot))
        self._direction = (p1 - p0) / distance if distance > 1e-9 else np.zeros(3)
        self._axis = rot / angle if angle > 1e-9 else np.zeros(3)
        inp = self._inp
        inp.current_position, inp.current_velocity, inp.current_acceleration = (
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
        )
        inp.target_position = [distance, angle]
        inp.target_velocity, inp.target_acceleration = [0.0, 0.0], [0.0, 0.0]
        self._done = outside or (distance <= 1e-9 and angle <= 1e-9)
        goal = (p1.tolist(), quaternion_of(r1))
        self._outs = (*start, *goal, self._done and not outside, outside)

    def kernel(self) -> Kernel:
        otg, inp, out = self._otg, self._inp, self._out
        working, finished = Result.Working, Result.Finished

        def line(t_s: float) -> Outputs:
            if self._done:
                return self._outs
            result = ruckig_step(otg, inp, out)
            if result not in (working, finished):  # Ruckig refused: hold where the path is
                return self._outs
            (s, phi), (ds, dphi) = out.new_position, out.new_velocity
            out.pass_to_input(inp)
            position = (self._p0 + s * self._direction).tolist()
            rotation = pin.exp3(phi * self._axis) @ self._r0
            twist = (ds * self._direction).tolist() + (dphi * self._axis).tolist()
            self._done = result == finished
            o = self._outs
            self._outs = (position, quaternion_of(rotation), twist, o[3], o[4], self._done, False)
            return self._outs

        return line


def inside_workspace(model: RobotModel, position_m: np.ndarray) -> bool:
    """Whether a point (base frame, m) is in the config's `[workspace]` (a box and/or a sphere)."""
    w = model.workspace
    if w.box_min_m and not (np.all(position_m >= w.box_min_m) and np.all(position_m <= w.box_max_m)):
        return False
    return not (
        w.sphere_radius_m > 0.0
        and np.linalg.norm(position_m - np.array(w.sphere_center_m)) > w.sphere_radius_m
    )


def _rpy(values: np.ndarray) -> np.ndarray:
    return np.asarray(pin.rpy.rpyToMatrix(*values.tolist()))


@register("line_to_pose")
class LineToPose(_Line):
    """A straight line to the pose `target_position_m`, `target_rpy_rad` (base frame; roll,
    pitch, yaw about the base's fixed x, y, z)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.target = self.add_parameter(
            "target_position_m",
            [0.0, 0.0, 0.0],
            bounds=(-20.0, 20.0),
            unit="m",
            shape=(3,),
            required=True,
            per_joint=True,
            element="axis",
        )
        self.target_rpy = self.add_parameter(
            "target_rpy_rad",
            [0.0, 0.0, 0.0],
            bounds=(-math.pi, math.pi),
            unit="rad",
            shape=(3,),
            required=True,
            per_joint=True,
            element="axis",
        )

    def _goal(self, p0: np.ndarray, r0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.target.value.copy(), _rpy(self.target_rpy.value)

    def configure(self, values: dict[str, Any]) -> None:
        """The target checked against the workspace as it is set: a mission whose goal is out of
        it is refused at `load` (a line by an offset can only be checked when it starts)."""
        super().configure(values)
        if "target_position_m" in values and not inside_workspace(self.ctx.model, self.target.value):
            where = ", ".join(f"{v:g}" for v in self.target.value.tolist())
            detail = f"(=[{where}]) is outside the workspace ([workspace] of the robot config)"
            raise ParameterError(f"{self.target.path} {detail}", name=self.target.name, detail=detail)


class _LineByOffset(_Line):
    """Base of the relative lines: `offset_m` and `rotation_rpy_rad` from where the tool starts;
    `_goal` says on whose axes."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        for key, unit, lo, hi, required in (
            ("offset_m", "m", -5.0, 5.0, True),
            ("rotation_rpy_rad", "rad", -math.pi, math.pi, False),
        ):
            self.add_parameter(
                key, [0.0] * 3, bounds=(lo, hi), unit=unit, shape=(3,), required=required,
                per_joint=True, element="axis",
            )  # fmt: skip
        self.offset, self.rotation = self.parameters["offset_m"], self.parameters["rotation_rpy_rad"]


@register("line_by_offset")
class LineByOffset(_LineByOffset):
    """A straight line by `offset_m` from where the tool starts, on the base's axes, turning it
    by `rotation_rpy_rad` about the base's axes."""

    def _goal(self, p0: np.ndarray, r0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return p0 + self.offset.value, _rpy(self.rotation.value) @ r0


@register("line_by_tool_offset")
class LineByToolOffset(_LineByOffset):
    """A straight line by `offset_m` on the tool's own axes (an approach along its z), turning it
    by `rotation_rpy_rad` about its own axes."""

    def _goal(self, p0: np.ndarray, r0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return p0 + r0 @ self.offset.value, r0 @ _rpy(self.rotation.value)


@register("pose_hold")
class PoseHold(KernelModule):
    """Holds the tool's pose of when the task starts: that pose, at rest, as the desired pose."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_output("position_des_m", (3,), "m")
        self.add_output("orientation_des", (4,), "1")
        self.add_output("twist_des", (6,), TWIST_UNIT)
        self._kin = ToolKinematics(ctx.model)
        self._outs: tuple[list[float], list[float], list[float]] = ([0.0] * 3, IDENTITY_QUATERNION, [0.0] * 6)

    def start(self, state: JointState) -> None:
        pose = self._kin.pose(state.q_rad)
        self._outs = (pose.translation.tolist(), quaternion_of(pose.rotation), [0.0] * 6)

    def kernel(self) -> Kernel:
        def hold(t_s: float) -> tuple[list[float], list[float], list[float]]:
            return self._outs

        return hold


__all__ = [
    "LineByOffset",
    "LineByToolOffset",
    "LineToPose",
    "PoseError",
    "PoseHold",
    "ToolPose",
    "angle_between",
    "inside_workspace",
]
