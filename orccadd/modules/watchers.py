"""Watchers: modules that turn measured signals into events (a boolean `fired` output).

The task's reactive shell maps a watcher's `fired` to a postcondition, a type 1/2/3 exception
or a synchronisation signal; the event is emitted on the rising edge.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.state import JointState
from orccadd.vec import max_abs, max_abs_diff, outside


class Watcher(KernelModule):
    """Base of watchers: a `fired` output and a debounce (`ticks` in a row before firing).
    Written as kernels (`Module.kernel`): a condition on plain values, debounced."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.fired = self.add_output("fired", (), "bool", dtype=np.bool_)
        self.ticks = self.add_parameter(
            "ticks", 1, bounds=(1, 100000), unit="ticks", tunable=True, integer=True
        )
        self._count = 0
        self._ticks_needed = 1

    def start(self, state: JointState) -> None:
        self._count = 0
        self.fired.value[...] = False

    def on_parameter_change(self, name: str) -> None:
        self._ticks_needed = int(self.ticks.value)

    def _debounce(self, condition: bool) -> tuple[bool]:
        self._count = count = self._count + 1 if condition else 0
        return (count >= self._ticks_needed,)


@register("tracking_error_watch")
class TrackingErrorWatch(Watcher):
    """Fires when max |q_des − q| exceeds `threshold_rad` (for `ticks` ticks in a row)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q = self.add_input("q", (n,), "rad")
        self.q_des = self.add_input("q_des", (n,), "rad")
        self.threshold = self.add_parameter(
            "threshold_rad", 0.05, bounds=(1e-6, 10.0), unit="rad", tunable=True
        )

    def kernel(self) -> Kernel:
        threshold, debounce = self.threshold.value, self._debounce

        def tracking_error(t_s: float, q: list[float], q_des: list[float]) -> tuple[bool]:
            return debounce(max_abs_diff(q_des, q) > float(threshold))

        return tracking_error


@register("joint_limit_watch")
class JointLimitWatch(Watcher):
    """Fires when a joint comes within `margin_rad` of its position limits or exceeds
    `velocity_fraction` of its maximum velocity."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n, m = ctx.dof, ctx.model
        self.q = self.add_input("q", (n,), "rad")
        self.dq = self.add_input("dq", (n,), "rad/s")
        self.margin = self.add_parameter("margin_rad", 0.05, bounds=(0.0, 1.0), unit="rad", tunable=True)
        # at most 1: beyond max_velocity the resource acts itself (its velocity guard cuts torques,
        # position and velocity commands are clamped, a measured excess is a type 3 LimitViolation)
        self.vfrac = self.add_parameter("velocity_fraction", 0.95, bounds=(0.01, 1.0), unit="1", tunable=True)
        self._lo, self._hi, self._vmax = m.q_min_rad, m.q_max_rad, m.v_max_rad_s
        # the bounds that fire, as lists (set from the parameters)
        self._q_lo: list[float] = []
        self._q_hi: list[float] = []
        self._dq_hi: list[float] = []
        self._dq_lo: list[float] = []
        self.on_parameter_change("margin_rad")

    def on_parameter_change(self, name: str) -> None:
        super().on_parameter_change(name)
        margin = float(self.margin.value)
        self._q_lo = (self._lo + margin).tolist()
        self._q_hi = (self._hi - margin).tolist()
        self._dq_hi = (self._vmax * float(self.vfrac.value)).tolist()
        self._dq_lo = [-v for v in self._dq_hi]

    def kernel(self) -> Kernel:
        debounce = self._debounce

        def joint_limit(t_s: float, q: list[float], dq: list[float]) -> tuple[bool]:
            near = outside(q, self._q_lo, self._q_hi)
            return debounce(near or outside(dq, self._dq_lo, self._dq_hi))

        return joint_limit


@register("target_reached")
class TargetReached(Watcher):
    """Postcondition: every |q − q_goal| < `tolerance_rad` and every |dq| < `velocity_tolerance_rad_s`."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q = self.add_input("q", (n,), "rad")
        self.dq = self.add_input("dq", (n,), "rad/s")
        self.q_goal = self.add_input("q_goal", (n,), "rad")
        self.tol = self.add_parameter("tolerance_rad", 0.005, bounds=(1e-6, 1.0), unit="rad", tunable=True)
        self.vtol = self.add_parameter(
            "velocity_tolerance_rad_s", 0.01, bounds=(1e-6, 10.0), unit="rad/s", tunable=True
        )

    def kernel(self) -> Kernel:
        tol, vtol, debounce = self.tol.value, self.vtol.value, self._debounce

        def reached(t_s: float, q: list[float], dq: list[float], q_goal: list[float]) -> tuple[bool]:
            ok = max_abs_diff(q_goal, q) < float(tol)
            return debounce(ok and max_abs(dq) < float(vtol))

        return reached


@register("timeout_watch")
class TimeoutWatch(Watcher):
    """Fires `timeout_s` after the task started."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.timeout = self.add_parameter("timeout_s", 10.0, bounds=(0.0, 1e6), unit="s", tunable=True)
        self._t0 = 0.0

    def start(self, state: JointState) -> None:
        super().start(state)
        self._t0 = state.t_s

    def kernel(self) -> Kernel:
        timeout, debounce = self.timeout.value, self._debounce

        def timed_out(t_s: float) -> tuple[bool]:
            return debounce(t_s - self._t0 >= float(timeout) - 1e-9)

        return timed_out


class _GraspWatch(Watcher):
    """A gripper closing on its goal with a limited force (current-based position mode): its
    joints' torque and speed tell whether something is between the fingers."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q = self.add_input("q", (n,), "rad")
        self.dq = self.add_input("dq", (n,), "rad/s")
        self.tau = self.add_input("tau", (n,), "N.m")
        self.q_goal = self.add_input("q_goal", (n,), "rad")
        self.grip = self.add_parameter(
            "grip_torque_nm", 0.2, bounds=(1e-4, 1e4), unit="N.m", tunable=True,
        )  # fmt: skip
        self.tol = self.add_parameter("tolerance_rad", 0.02, bounds=(1e-6, 1.0), unit="rad", tunable=True)
        self.vtol = self.add_parameter(
            "velocity_tolerance_rad_s", 0.02, bounds=(1e-6, 10.0), unit="rad/s", tunable=True
        )


@register("grasp_watch")
class GraspWatch(_GraspWatch):
    """Postcondition `Grasped`: at rest short of the goal (by more than `tolerance_rad`), pressing
    with at least `grip_torque_nm` on some joint: an object holds the fingers apart."""

    def kernel(self) -> Kernel:
        grip, tol, vtol, debounce = self.grip.value, self.tol.value, self.vtol.value, self._debounce

        def grasped(
            t_s: float, q: list[float], dq: list[float], tau: list[float], q_goal: list[float]
        ) -> tuple[bool]:
            held = max_abs(tau) >= float(grip) and max_abs_diff(q_goal, q) > float(tol)
            return debounce(held and max_abs(dq) < float(vtol))

        return grasped


@register("grasp_missed_watch")
class GraspMissedWatch(_GraspWatch):
    """Type 2 `Missed`: closed to the goal (within `tolerance_rad`, at rest) pressing on nothing
    (torque below `grip_torque_nm`): the object was not there."""

    def kernel(self) -> Kernel:
        grip, tol, vtol, debounce = self.grip.value, self.tol.value, self.vtol.value, self._debounce

        def missed(
            t_s: float, q: list[float], dq: list[float], tau: list[float], q_goal: list[float]
        ) -> tuple[bool]:
            closed = max_abs_diff(q_goal, q) <= float(tol) and max_abs(tau) < float(grip)
            return debounce(closed and max_abs(dq) < float(vtol))

        return missed


@register("force_watch")
class ForceWatch(Watcher):
    """Fires when the force at the tool exceeds `force_n` (its magnitude) or, if `torque_nm` > 0,
    its torque exceeds `torque_nm`: a contact, or a push harder than the task allows. Wired to a
    resource that measures the wrench (`arm.wrench` on a UR: actual_TCP_force, N and N·m)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.wrench = self.add_input("wrench", (6,), "N|N.m")
        self.force = self.add_parameter("force_n", 20.0, bounds=(0.01, 1e5), unit="N", tunable=True)
        self.torque = self.add_parameter("torque_nm", 0.0, bounds=(0.0, 1e4), unit="N.m", tunable=True)

    def kernel(self) -> Kernel:
        force, torque, debounce = self.force.value, self.torque.value, self._debounce

        def over_force(t_s: float, wrench: list[float]) -> tuple[bool]:
            fx, fy, fz, tx, ty, tz = wrench
            pushed = fx * fx + fy * fy + fz * fz > float(force) ** 2
            twisted = float(torque) > 0.0 and tx * tx + ty * ty + tz * tz > float(torque) ** 2
            return debounce(pushed or twisted)

        return over_force


class _SignalWatch(Watcher):
    """Base of the one-number signal watchers (`value`, unit "1": a resource's
    `arm.target_visible`, `arm.speed_scaling`): fires after `ticks` ticks in a row on the side of
    `threshold` that `BELOW` says; a value that is not finite does not fire."""

    BELOW: ClassVar[bool] = True

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("value", (1,), "1")
        self.threshold = self.add_parameter(
            "threshold", 0.5, bounds=(-1e9, 1e9), unit="1", required=True, tunable=True
        )

    def kernel(self) -> Kernel:
        threshold, debounce, below = self.threshold.value, self._debounce, self.BELOW

        def crossed(t_s: float, value: list[float]) -> tuple[bool]:
            v = value[0]
            return debounce(math.isfinite(v) and (v < float(threshold)) == below)

        return crossed


@register("signal_below_watch")
class SignalBelowWatch(_SignalWatch):
    """Fires when a one-number signal stays below `threshold` for `ticks` ticks in a row: a
    target lost (`target_visible` below 0.5), a controller slowed."""


@register("signal_above_watch")
class SignalAboveWatch(_SignalWatch):
    """Fires when a one-number signal stays at or above `threshold` for `ticks` ticks in a row: a
    target seen again (`arm.target_visible` at 1)."""

    BELOW = False
