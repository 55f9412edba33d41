"""The controller's own trajectory generation: what servoj, speedj, movej and stopj make of
their arguments, one controller cycle at a time.

Each motion advances the target state (`target_q`, `target_qd`, `target_qdd`) by one cycle
`h_s` and says when it has finished. The planned motions (movej, speedj, stopj) keep within the
joint speed and acceleration limits: a leading axis moves with the asked speed and acceleration,
the others are scaled so every joint starts and ends together, and the leading values are
lowered until no joint exceeds its own limits (URScript: "a: joint acceleration of leading
axis", "v: joint speed of leading axis"). servoj is the client's trajectory: it follows it as
asked, and the controller's safety checks what it makes of it (`controller.py`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from orccadd.state import FloatArray

EPS = 1e-9


class Target:
    """The controller's target state (rad, rad/s, rad/s²), updated in place."""

    def __init__(self, n: int) -> None:
        self.q = np.zeros(n)
        self.qd = np.zeros(n)
        self.qdd = np.zeros(n)

    def hold(self, q: FloatArray) -> None:
        self.q[:] = q
        self.qd[:] = 0.0
        self.qdd[:] = 0.0


def leading_limit(asked: float, share: FloatArray, limit: FloatArray) -> float:
    """The leading axis's value `asked`, lowered so that no joint's `asked·share` exceeds its
    `limit` (`share` = each joint's fraction of the leading axis's motion, in [0, 1])."""
    with np.errstate(divide="ignore"):
        caps = np.where(share > EPS, limit / np.maximum(share, EPS), math.inf)
    return float(min(asked, caps.min()))


class Motion(ABC):
    """One motion command; `step` advances `tgt` by `h_s` and returns True once finished.
    A `scaled` motion runs at the speed slider's `speed_fraction` (set by the controller before
    each step: `speed_scaling.SpeedScaling`)."""

    name = "motion"
    scaled = False
    speed_fraction = 1.0

    @abstractmethod
    def step(self, tgt: Target, h_s: float) -> bool: ...


class Hold(Motion):
    """At rest where the target is."""

    name = "hold"

    def step(self, tgt: Target, h_s: float) -> bool:
        tgt.qd[:] = 0.0
        tgt.qdd[:] = 0.0
        return True


class DirectTorque(Motion):
    """Direct joint torque control (`direct_torque`, PolyScope 5.23+): the joints take the torques
    commanded on top of the controller's gravity compensation, the target follows the arm (the
    controller steps them; `UrController.step`). Called every cycle, or the robot "returns to
    position control mode" (UR's script manual): a cycle without a `direct_torque` ends it, held
    where the arm is."""

    name = "direct_torque"

    def __init__(self, n: int) -> None:
        self.tau_nm = np.zeros(n)
        self.fresh = False  # `direct_torque` called since the last cycle

    def set(self, tau_nm: FloatArray) -> None:
        self.tau_nm[:] = tau_nm
        self.fresh = True

    def step(self, tgt: Target, h_s: float) -> bool:
        if self.fresh:
            self.fresh = False
            return False
        tgt.qd[:] = 0.0
        tgt.qdd[:] = 0.0
        return True


class StopJ(Motion):
    """Decelerate every joint to rest together, the fastest at `a` rad/s² (stopj)."""

    name = "stopj"

    def __init__(self, a_rad_s2: float, a_max_rad_s2: FloatArray) -> None:
        self.a = a_rad_s2
        self.a_max = a_max_rad_s2
        self._decel: FloatArray | None = None
        self._left_s = 0.0

    def step(self, tgt: Target, h_s: float) -> bool:
        if self._decel is None:
            lead = float(np.abs(tgt.qd).max())
            if lead < EPS:
                tgt.qd[:] = 0.0
                tgt.qdd[:] = 0.0
                return True
            a = leading_limit(max(self.a, EPS), np.abs(tgt.qd) / lead, self.a_max)
            self._left_s = lead / a
            self._decel = tgt.qd / self._left_s
        dt = min(h_s, self._left_s)
        qd0 = tgt.qd.copy()
        tgt.qd -= self._decel * dt
        tgt.q += 0.5 * (qd0 + tgt.qd) * dt
        tgt.qdd[:] = -self._decel
        self._left_s -= dt
        if self._left_s <= EPS:
            tgt.qd[:] = 0.0
            tgt.qdd[:] = 0.0
            return True
        return False


class MoveJ(Motion):
    """Move to `q_goal` in joint space from rest: a trapezoidal speed profile on the leading
    axis (speed `v`, acceleration `a`), every joint arriving together (movej). Planned at its
    first step, from the target it then finds; played in scaled time (the speed slider)."""

    name = "movej"
    scaled = True

    def __init__(
        self,
        q_goal_rad: FloatArray,
        v_rad_s: float,
        a_rad_s2: float,
        v_max_rad_s: FloatArray,
        a_max_rad_s2: FloatArray,
    ) -> None:
        self.goal = np.array(q_goal_rad, dtype=np.float64)
        self.v, self.a = v_rad_s, a_rad_s2
        self.v_max, self.a_max = v_max_rad_s, a_max_rad_s2
        self._start: FloatArray | None = None
        self._dir = np.zeros_like(self.goal)  # Δq / L
        self._length = 0.0
        self._t_s = 0.0
        self._t_acc = self._t_total = 0.0
        self._v_lead = self._a_lead = 0.0

    def _plan(self, q0: FloatArray) -> None:
        self._start = q0.copy()
        delta = self.goal - q0
        self._length = float(np.abs(delta).max())
        if self._length < EPS:
            return
        self._dir = delta / self._length
        share = np.abs(self._dir)
        v = leading_limit(max(self.v, EPS), share, self.v_max)
        a = leading_limit(max(self.a, EPS), share, self.a_max)
        if self._length >= v * v / a:  # reaches cruising speed
            self._t_acc = v / a
            self._t_total = self._length / v + self._t_acc
        else:  # triangular
            self._t_acc = math.sqrt(self._length / a)
            self._t_total = 2.0 * self._t_acc
            v = a * self._t_acc
        self._v_lead, self._a_lead = v, a

    def _profile(self, t: float) -> tuple[float, float, float]:
        """Leading axis (distance, speed, acceleration) at `t` seconds."""
        a, v, ta, tt = self._a_lead, self._v_lead, self._t_acc, self._t_total
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        if t < ta:
            return 0.5 * a * t * t, a * t, a
        if t < tt - ta:
            return 0.5 * a * ta * ta + v * (t - ta), v, 0.0
        if t < tt:
            r = tt - t
            return self._length - 0.5 * a * r * r, a * r, -a
        return self._length, 0.0, 0.0

    def step(self, tgt: Target, h_s: float) -> bool:
        if self._start is None:
            self._plan(tgt.q)
        assert self._start is not None
        if self._length < EPS:
            tgt.hold(self.goal)
            return True
        f = self.speed_fraction
        self._t_s += h_s * f
        s, sd, sdd = self._profile(self._t_s)
        tgt.q[:] = self._start + self._dir * s
        tgt.qd[:] = self._dir * (sd * f)
        tgt.qdd[:] = self._dir * (sdd * f * f)
        if self._t_s >= self._t_total:
            tgt.hold(self.goal)
            return True
        return False


class SpeedJ(Motion):
    """Accelerate to joint speeds `qd` (the fastest change at `a` rad/s²) and keep them (speedj,
    repeated by the control script until a stop); the speed slider scales the speeds (and the
    acceleration by its square)."""

    name = "speedj"
    scaled = True

    def __init__(self, a_max_rad_s2: FloatArray) -> None:
        self.a_max = a_max_rad_s2
        self.qd_ref = np.zeros_like(a_max_rad_s2)
        self.a = 0.5

    def set(self, qd_rad_s: FloatArray, a_rad_s2: float) -> None:
        self.qd_ref[:] = qd_rad_s
        self.a = a_rad_s2

    def step(self, tgt: Target, h_s: float) -> bool:
        f = self.speed_fraction
        delta = self.qd_ref * f - tgt.qd
        lead = float(np.abs(delta).max())
        qd0 = tgt.qd.copy()
        if lead > EPS:
            a = leading_limit(max(self.a * f * f, EPS), np.abs(delta) / lead, self.a_max)
            tgt.qd += delta * (min(lead, a * h_s) / lead)
        tgt.qdd[:] = (tgt.qd - qd0) / h_s
        tgt.q += 0.5 * (qd0 + tgt.qd) * h_s
        return False


class ServoJ(Motion):
    """Follow the streamed joint targets (servoj; `set` before the first step): the servo
    drives the target's position predicted `lookahead` seconds ahead onto the streamed position
    with `gain` (1/s²):

        q̈ = gain·(q_servo − q) − gain·lookahead·q̇

    so a target moving at a steady speed is followed `lookahead` seconds late, a larger gain
    follows faster and a longer lookahead smooths more (URScript: "lookahead_time smoothens the
    trajectory", "gain: proportional gain for following target position"). Integrated
    implicitly (stable at any cycle time)."""

    name = "servoj"

    def __init__(self, n: int) -> None:
        self.q_ref = np.zeros(n)
        self.lookahead_s = 0.1
        self.gain = 300.0

    def set(self, q_rad: FloatArray, lookahead_s: float, gain: float) -> None:
        self.q_ref[:] = q_rad
        self.lookahead_s = min(max(lookahead_s, 0.03), 0.2)
        self.gain = min(max(gain, 100.0), 2000.0)

    def step(self, tgt: Target, h_s: float) -> bool:
        k = self.gain
        c = k * self.lookahead_s
        qd0 = tgt.qd.copy()
        tgt.qd += h_s * k * (self.q_ref - tgt.q)
        tgt.qd /= 1.0 + h_s * c + h_s * h_s * k
        tgt.q += h_s * tgt.qd
        tgt.qdd[:] = (tgt.qd - qd0) / h_s
        return False
