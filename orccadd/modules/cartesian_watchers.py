"""Watchers in task space: a pose reached, a Cartesian tracking error, nearness to a singularity.

Wired to the outputs of `tool_pose`, `pose_error` and the line trajectories
(orccadd/modules/cartesian.py); the task's shell maps each `fired` to a postcondition or an
exception, as for the joint-space watchers (orccadd/modules/watchers.py).
"""

from __future__ import annotations

import math

import numpy as np

from orccadd.kinematics import rotation_error
from orccadd.modules.base import Kernel, ModuleContext, register
from orccadd.modules.cartesian import TWIST_UNIT
from orccadd.modules.watchers import Watcher


@register("pose_reached")
class PoseReached(Watcher):
    """Postcondition: the tool within `tolerance_m` and `tolerance_rad` of the goal pose, its
    linear and angular speeds below `velocity_tolerance_m_s` and `velocity_tolerance_rad_s`."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("position_m", (3,), "m")
        self.add_input("orientation", (4,), "1")
        self.add_input("twist", (6,), TWIST_UNIT)
        self.add_input("position_goal_m", (3,), "m")
        self.add_input("orientation_goal", (4,), "1")
        self.tol = self.add_parameter("tolerance_m", 0.001, bounds=(1e-6, 1.0), unit="m", tunable=True)
        self.rtol = self.add_parameter("tolerance_rad", 0.01, bounds=(1e-6, 3.2), unit="rad", tunable=True)
        self.vtol = self.add_parameter(
            "velocity_tolerance_m_s", 0.005, bounds=(1e-6, 10.0), unit="m/s", tunable=True
        )
        self.wtol = self.add_parameter(
            "velocity_tolerance_rad_s", 0.02, bounds=(1e-6, 10.0), unit="rad/s", tunable=True
        )

    def kernel(self) -> Kernel:
        debounce = self._debounce
        tol, rtol, vtol, wtol = self.tol.value, self.rtol.value, self.vtol.value, self.wtol.value

        def reached(
            t_s: float,
            p: list[float],
            o: list[float],
            twist: list[float],
            p_goal: list[float],
            o_goal: list[float],
        ) -> tuple[bool]:
            near = sum((a - b) ** 2 for a, b in zip(p, p_goal, strict=True)) < float(tol) ** 2
            vx, vy, vz, wx, wy, wz = twist
            still = (
                vx * vx + vy * vy + vz * vz < float(vtol) ** 2
                and wx * wx + wy * wy + wz * wz < float(wtol) ** 2
            )
            turned = near and still and math.hypot(*rotation_error(o, o_goal)) < float(rtol)
            return debounce(turned)

        return reached


@register("pose_error_watch")
class PoseErrorWatch(Watcher):
    """Fires when the tool is more than `threshold_m` from the desired position or, if
    `threshold_rad` > 0, more than that from the desired orientation (wire `pose_error`'s
    `distance_m` and `angle_rad`): a Cartesian tracking error."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("distance_m", (), "m")
        self.add_input("angle_rad", (), "rad")
        self.threshold = self.add_parameter("threshold_m", 0.005, bounds=(1e-6, 10.0), unit="m", tunable=True)
        self.rthreshold = self.add_parameter(
            "threshold_rad", 0.0, bounds=(0.0, 3.2), unit="rad", tunable=True
        )

    def kernel(self) -> Kernel:
        debounce, threshold, rthreshold = self._debounce, self.threshold.value, self.rthreshold.value

        def pose_error(t_s: float, distance_m: float, angle_rad: float) -> tuple[bool]:
            turned = float(rthreshold) > 0.0 and angle_rad > float(rthreshold)
            return debounce(distance_m > float(threshold) or turned)

        return pose_error


@register("below_watch")
class BelowWatch(Watcher):
    """Fires when a dimensionless scalar (`measure`) stays below `threshold` (and is finite) for
    `ticks` ticks: `image_servo`'s `feature_error` converged (servo_visual.toml's
    postcondition). A resource's one-number signal: `signal_below_watch`."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("measure", (), "1")
        self.threshold = self.add_parameter("threshold", 0.01, bounds=(0.0, 10.0), unit="1", tunable=True)

    def kernel(self) -> Kernel:
        debounce, threshold = self._debounce, self.threshold.value

        def below(t_s: float, measure: float) -> tuple[bool]:
            return debounce(bool(np.isfinite(measure)) and measure < float(threshold))

        return below


@register("manipulability_watch")
class ManipulabilityWatch(BelowWatch):
    """Fires when a nearness-to-singularity measure (`tool_pose`'s `manipulability`, or
    `resolved_rate`'s `smallest_singular_value`) falls below `threshold`: the arm is coming to a
    configuration where the tool cannot move in some direction."""


@register("wrench_settled")
class WrenchSettled(Watcher):
    """Fires when a force law's error (`hybrid_force`'s `wrench_error`) stays within
    `tolerance_n` (its force's magnitude) and `tolerance_nm` (its torque's): the setpoint is
    held, e.g. a press's postcondition."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("wrench_error", (6,), "N|N.m")
        self.tol = self.add_parameter("tolerance_n", 1.0, bounds=(1e-3, 1e4), unit="N", tunable=True)
        self.ttol = self.add_parameter("tolerance_nm", 0.1, bounds=(1e-4, 1e3), unit="N.m", tunable=True)

    def kernel(self) -> Kernel:
        debounce, tol, ttol = self._debounce, self.tol.value, self.ttol.value

        def settled(t_s: float, wrench_error: list[float]) -> tuple[bool]:
            fx, fy, fz, tx, ty, tz = wrench_error
            held = (
                fx * fx + fy * fy + fz * fz <= float(tol) ** 2
                and tx * tx + ty * ty + tz * tz <= float(ttol) ** 2
            )
            return debounce(held)

        return settled


@register("plane_crossed")
class PlaneCrossed(Watcher):
    """Fires when the tool's point is past a plane: (p − `point_m`)·`normal` < 0, the plane
    through `point_m` with the normal `normal` (base frame; need not be unit). An insertion
    deep enough, a tool below a height."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("position_m", (3,), "m")
        self.point = self.add_parameter(
            "point_m", [0.0, 0.0, 0.0], bounds=(-20.0, 20.0), unit="m", shape=(3,), required=True,
            per_joint=True, element="axis", tunable=True,
        )  # fmt: skip
        self.normal = self.add_parameter(
            "normal",
            [0.0, 0.0, 1.0],
            bounds=(-1.0, 1.0),
            unit="1",
            shape=(3,),
            per_joint=True,
            element="axis",
        )

    def kernel(self) -> Kernel:
        debounce, point, normal = self._debounce, self.point.value, self.normal.value

        def crossed(t_s: float, position_m: list[float]) -> tuple[bool]:
            (px, py, pz), (ox, oy, oz), (nx, ny, nz) = position_m, point.tolist(), normal.tolist()
            return debounce((px - ox) * nx + (py - oy) * ny + (pz - oz) * nz < 0.0)

        return crossed
