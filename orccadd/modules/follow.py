"""Following a planner's joint trajectory: time-stamped points, interpolated by a cubic spline.

`JointTrajectory` holds the points (`t_s` strictly increasing from 0, one row of joint positions
per point). `Spline` interpolates them with the clamped cubic spline: a cubic in time between
consecutive points, through every point, continuous in position, velocity and acceleration (C2,
more than the C1 cubic of ros2_control's joint_trajectory_controller given positions and
velocities), at rest at the first and the last point. Its velocities and accelerations are exact
piecewise polynomials, so `first_excess` checks the whole interpolated motion, between the
points too, against the joints' limits before anything moves.

The module `joint_trajectory_follow` plays the spline from the tick its law starts; it takes the
points as data (`Module.set_data`, at build time: never a file in a tick).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orccadd.errors import ParameterError
from orccadd.modules.base import FloatArray, Kernel, KernelModule, ModuleContext, register
from orccadd.state import JointState

MAX_POINTS = 100_000  # ~7 MB of CSV for six joints; a planner's trajectory has far fewer

Outputs = tuple[list[float], list[float], list[float], list[float], bool]


@dataclass(frozen=True)
class JointTrajectory:
    """Points of a joint trajectory: `t_s` (N,) in s, strictly increasing from 0; `q_rad` (N, dof)."""

    t_s: FloatArray
    q_rad: FloatArray

    def problem(self, dof: int) -> str:
        """Why these points are not a trajectory of `dof` joints ("" if they are)."""
        t, q = self.t_s, self.q_rad
        if t.ndim != 1 or q.shape != (len(t), dof):
            return f"{q.shape} positions for {t.shape} times: want one row of {dof} per time"
        if not 2 <= len(t) <= MAX_POINTS:
            return f"{len(t)} points: a trajectory has 2 to {MAX_POINTS}"
        if not (np.isfinite(t).all() and np.isfinite(q).all()):
            return "a time or a position is not a finite number"
        if t[0] != 0.0 or not (np.diff(t) > 0).all():
            return "the times must increase strictly from 0"
        return ""


class Spline:
    """The clamped cubic spline through a trajectory's points (zero velocity at both ends).

    Segment k (from point k to k + 1, s = t - t_k in [0, h_k]) is
    q(s) = c0 + c1·s + c2·s² + c3·s³, per joint; the arrays are (N - 1, dof). Not for a tick."""

    def __init__(self, traj: JointTrajectory) -> None:
        t, q = traj.t_s, traj.q_rad
        h = np.diff(t)[:, None]
        d = np.diff(q, axis=0)
        m = knot_velocities(h[:, 0], d)
        self.t_s, self.h = t, h
        self.c0, self.c1 = q[:-1], m[:-1]
        self.c2 = (3.0 * d / h - 2.0 * m[:-1] - m[1:]) / h
        self.c3 = (m[:-1] + m[1:] - 2.0 * d / h) / (h * h)
        self.end_rad = q[-1]

    def at(self, t_s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Positions, velocities, accelerations at times `t_s` (each (len, dof); for tests)."""
        k = np.clip(np.searchsorted(self.t_s, t_s, side="right") - 1, 0, len(self.h) - 1)
        s = np.clip(t_s - self.t_s[k], 0.0, self.h[k, 0])[:, None]
        c0, c1, c2, c3 = self.c0[k], self.c1[k], self.c2[k], self.c3[k]
        return (
            c0 + s * (c1 + s * (c2 + s * c3)),
            c1 + s * (2.0 * c2 + 3.0 * s * c3),
            2.0 * c2 + 6.0 * s * c3,
        )


def knot_velocities(h: FloatArray, d: FloatArray) -> FloatArray:
    """The velocity at each point (N, dof) that makes the cubic Hermite segments C2, zero at
    the ends: the tridiagonal system m[i-1]/h[i-1] + 2(1/h[i-1] + 1/h[i])·m[i] + m[i+1]/h[i]
    = 3(d[i-1]/h[i-1]² + d[i]/h[i]²), solved by the Thomas algorithm (diagonally dominant)."""
    n = len(h) + 1
    m = np.zeros((n, d.shape[1]))
    if n <= 2:
        return m
    inv = 1.0 / h
    diag = 2.0 * (inv[:-1] + inv[1:])
    rhs = 3.0 * (d[:-1] * (inv[:-1] ** 2)[:, None] + d[1:] * (inv[1:] ** 2)[:, None])
    cp = np.zeros(n - 2)
    dp = np.zeros_like(rhs)
    for i in range(n - 2):  # forward sweep; sub- and super-diagonal entries are 1/h
        lower = inv[i] if i else 0.0
        denom = diag[i] - lower * (cp[i - 1] if i else 0.0)
        cp[i] = inv[i + 1] / denom
        dp[i] = (rhs[i] - lower * (dp[i - 1] if i else 0.0)) / denom
    for i in range(n - 3, -1, -1):  # back substitution
        m[i + 1] = dp[i] - (cp[i] * m[i + 2] if i < n - 3 else 0.0)
    return m


@dataclass(frozen=True)
class Excess:
    """The first place the interpolated motion leaves a joint's limits: at point `row` (0-based),
    or, `between`, on the way from it to the next; `quantity` position, velocity or acceleration."""

    row: int
    joint: int
    quantity: str
    value: float
    limit: float
    between: bool


def first_excess(
    spline: Spline, q_min: FloatArray, q_max: FloatArray, v_max: FloatArray, a_max: FloatArray
) -> Excess | None:
    """The earliest place (by point, then segment) where the spline passes a limit, or None."""
    found: list[Excess] = []
    q = np.vstack([spline.c0, spline.end_rad[None, :]])
    for bad, bound in ((q < q_min, q_min), (q > q_max, q_max)):
        if bad.any():
            r, j = np.argwhere(bad)[0]
            found.append(Excess(int(r), int(j), "position", float(q[r, j]), float(bound[j]), False))
    h, c1, c2, c3 = spline.h, spline.c1, spline.c2, spline.c3
    with np.errstate(divide="ignore", invalid="ignore"):
        s_v = np.where(c3 != 0.0, -c2 / (3.0 * c3), 0.0)  # where |velocity| may peak inside
        inside = (s_v > 0.0) & (s_v < h)
        v_peak = np.where(inside, c1 + s_v * (2.0 * c2 + 3.0 * s_v * c3), 0.0)
        lo, hi = _position_range(spline)
    v_end = c1 + h * (2.0 * c2 + 3.0 * h * c3)
    v = np.maximum(np.maximum(np.abs(c1), np.abs(v_end)), np.abs(v_peak))
    a = np.maximum(np.abs(2.0 * c2), np.abs(2.0 * c2 + 6.0 * c3 * h))  # linear in time
    for value, over, bound, what in (
        (v, v > v_max, v_max, "velocity"),
        (a, a > a_max, a_max, "acceleration"),
        (lo, lo < q_min, q_min, "position"),
        (hi, hi > q_max, q_max, "position"),
    ):
        if over.any():
            r, j = np.argwhere(over)[0]
            found.append(Excess(int(r), int(j), what, float(value[r, j]), float(bound[j]), True))
    return min(found, key=lambda e: (e.row, e.between)) if found else None


def _position_range(spline: Spline) -> tuple[FloatArray, FloatArray]:
    """Each segment's lowest and highest position (its ends, and where its velocity is 0)."""
    h, c0, c1, c2, c3 = spline.h, spline.c0, spline.c1, spline.c2, spline.c3
    q_end = c0 + h * (c1 + h * (c2 + h * c3))
    lo, hi = np.minimum(c0, q_end), np.maximum(c0, q_end)
    disc = 4.0 * c2 * c2 - 12.0 * c1 * c3
    root = np.sqrt(np.maximum(disc, 0.0))
    quadratic = c3 != 0.0
    for sign in (1.0, -1.0):
        s = np.where(quadratic, (-2.0 * c2 + sign * root) / (6.0 * c3), -c1 / (2.0 * c2))
        ok = np.isfinite(s) & (s > 0.0) & (s < h) & (~quadratic | (disc >= 0.0))
        qs = np.where(ok, c0 + s * (c1 + s * (c2 + s * c3)), c0)
        lo, hi = np.minimum(lo, qs), np.maximum(hi, qs)
    return lo, hi


@register("joint_trajectory_follow")
class JointTrajectoryFollow(KernelModule):
    """Plays a planner's trajectory (`set_data`: a `JointTrajectory`) from the tick its law
    starts: the clamped cubic spline's position, velocity and acceleration (`q_des`, `dq_des`,
    `ddq_des`, as `ruckig_trajectory` gives them), `q_goal` the last point and `finished` once
    the last point's time has passed. It starts at the first point, whatever the arm's state:
    the daemon refuses a trajectory that does not start where the arm is (`orccadctl follow`)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q_des = self.add_output("q_des", (n,), "rad")
        self.dq_des = self.add_output("dq_des", (n,), "rad/s")
        self.ddq_des = self.add_output("ddq_des", (n,), "rad/s^2")
        self.q_goal = self.add_output("q_goal", (n,), "rad")
        self.finished = self.add_output("finished", (), "bool", dtype=np.bool_)
        self.spline: Spline | None = None
        self._zeros = [0.0] * n
        self._t: list[float] = []
        self._c: list[tuple[list[float], list[float], list[float], list[float]]] = []
        self._end: list[float] = ctx.model.home_rad.tolist()
        self._t0: float | None = None
        self._seg = 0

    def set_data(self, data: object) -> None:
        """The trajectory to play (not for a tick): its spline is computed here, once."""
        if not isinstance(data, JointTrajectory):
            raise ParameterError(
                f"{self.name}: takes a JointTrajectory, not {type(data).__name__}", name="trajectory"
            )
        if why := data.problem(self.ctx.dof):
            raise ParameterError(f"{self.name}: {why}", name="trajectory", detail=why)
        spline = self.spline = Spline(data)
        # in place: the compiled tick's kernel holds these lists (it is made when the task is built)
        self._t[:] = spline.t_s.tolist()
        rows = zip(
            spline.c0.tolist(), spline.c1.tolist(), spline.c2.tolist(), spline.c3.tolist(), strict=True
        )
        self._c[:] = rows
        self._end[:] = spline.end_rad.tolist()
        self.q_goal.value[:] = spline.end_rad

    def needs_data(self) -> bool:
        return self.spline is None

    def start(self, state: JointState) -> None:
        self._t0 = None  # the first tick of the law is the trajectory's time 0
        self._seg = 0
        first = self._c[0][0] if self._c else self._end
        self.q_des.value[:] = first
        self.dq_des.value[:] = 0.0
        self.ddq_des.value[:] = 0.0
        self.finished.value[...] = False

    def kernel(self) -> Kernel:
        t, c, zeros, dof = self._t, self._c, self._zeros, range(self.ctx.dof)

        def follow(t_s: float) -> Outputs:
            if self._t0 is None:
                self._t0 = t_s
            tau = t_s - self._t0
            end = self._end
            if not c or tau >= t[-1]:
                return (end, zeros, zeros, end, True)
            k = self._seg
            while t[k + 1] <= tau:
                k += 1
            self._seg = k
            s = tau - t[k]
            c0, c1, c2, c3 = c[k]
            q = [c0[j] + s * (c1[j] + s * (c2[j] + s * c3[j])) for j in dof]
            dq = [c1[j] + s * (2.0 * c2[j] + 3.0 * s * c3[j]) for j in dof]
            ddq = [2.0 * c2[j] + 6.0 * s * c3[j] for j in dof]
            return (q, dq, ddq, end, False)

        return follow
