"""What the arm can touch: a wall (a plane in the base frame) and an external push on the TCP.

The world gives the external wrench on the tool at the TCP, in the base frame ([Fx, Fy, Fz] N,
[Tx, Ty, Tz] N·m about the TCP): the arm's dynamics take it as joint torques (J_tcpᵀ·W, every
sub-step: `arm.UrArm`) and the flange's force/torque sensor measures it (`ft_sensor.FtSensor`).

The wall is a one-sided spring-damper at the TCP (a point contact, no friction): with `n` the
wall's unit normal (pointing out of the wall, into free space), `p0` a point of its surface and
the TCP at `p` moving at `v`,

    depth d = (p0 − p)·n        (> 0: the TCP is inside the wall)
    F = n · max(0, k·d − c·(v·n))   while d > 0, else 0

so the wall pushes the tool out along its normal and never pulls it in (the law and the
parameters' checks are the simulated arm's, `orccadd.physres.contact`, whose planes and holes
add friction and a tool radius). The push is a wrench
the test applies to the TCP for a while (a hand on the tool, in freedrive tests).

Set from the control channel (`faults.py`): `wall`, `wall_remove`, `push`; and the simulated
arm's shapes, `plane`, `hole` (a pocket with a rounded rim: a peg-in-hole), `tool` (the TCP a
sphere), `clear_world`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from orccadd.physres.contact import (
    DEFAULT_DAMPING_N_S_M,
    ContactWorld,
    hole_from_params,
    non_negative,
    normal_force,
    only,
    plane_from_params,
    unit_normal,
    vector3,
)
from orccadd.state import FloatArray

DEFAULT_WALL_DAMPING_N_S_M = DEFAULT_DAMPING_N_S_M


@dataclass(frozen=True)
class Wall:
    """A plane the TCP cannot pass without a reaction: `point_m` on its surface, `normal` the
    unit vector out of it (base frame), stiffness N/m and damping N·s/m."""

    point_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    stiffness_n_m: float
    damping_n_s_m: float = DEFAULT_WALL_DAMPING_N_S_M


@dataclass(frozen=True)
class Push:
    """A wrench on the TCP (base frame: N, N·m) until the controller's time `until_s`."""

    wrench: tuple[float, float, float, float, float, float]
    until_s: float


def wall_from_params(params: dict[str, Any]) -> Wall:
    """A wall from the control channel's `{"inject": "wall", ...}` (`ValueError` if bad)."""
    only(params, ("point_m", "normal", "stiffness_n_m", "damping_n_s_m"), "wall")
    point = vector3(params, "point_m")
    normal = unit_normal(params)
    stiffness = non_negative(params, "stiffness_n_m", None)
    damping = non_negative(params, "damping_n_s_m", DEFAULT_WALL_DAMPING_N_S_M, allow_zero=True)
    return Wall(point, normal, stiffness, damping)


def push_from_params(params: dict[str, Any], now_s: float) -> Push:
    """A push from `{"inject": "push", "force_n": [...], "torque_nm": [...], "duration_s": T}`."""
    only(params, ("force_n", "torque_nm", "duration_s"), "push")
    f = vector3(params, "force_n", [0.0, 0.0, 0.0])
    t = vector3(params, "torque_nm", [0.0, 0.0, 0.0])
    duration = non_negative(params, "duration_s", None)
    return Push((*f, *t), now_s + duration)


class World:
    """The wall, the push and the shapes (planes and holes, the simulated arm's:
    `orccadd.physres.contact`, on a TCP sphere of `shapes.tool_radius_m`), read by the arm's
    dynamics (any thread holding the controller's lock, or the cycle itself); replaced whole,
    never changed in place."""

    def __init__(self) -> None:
        self.wall: Wall | None = None
        self.push: Push | None = None
        self.shapes = ContactWorld()
        self.now_s = 0.0  # the controller's time, set by its cycle (the push's clock)

    @property
    def empty(self) -> bool:
        """Nothing to touch and no push: the dynamics skip the TCP's Jacobian."""
        return self.wall is None and self.push is None and not self.shapes.shapes

    def change(self, what: str, params: dict[str, Any]) -> None:
        """`plane` or `hole` added (`contact.plane_from_params`, `hole_from_params`), `tool` (the
        TCP a sphere of `radius_m`), `clear_world` (every shape, the wall and the push gone)."""
        if what == "plane":
            self.shapes.add(plane_from_params(params))
        elif what == "hole":
            self.shapes.add(hole_from_params(params))
        elif what == "tool":
            only(params, ("radius_m",), "tool")
            self.shapes.tool_radius_m = non_negative(params, "radius_m", None, allow_zero=True)
        else:  # clear_world
            only(params, (), "clear_world")
            self.shapes.clear()
            self.wall = self.push = None

    def wrench_at(self, p_m: FloatArray, v_m_s: FloatArray, out: FloatArray) -> bool:
        """The external wrench on the TCP at `p_m` moving at `v_m_s` (base frame) into `out`;
        False (and `out` zero) when there is none. Cheap when the world is empty."""
        wall, push = self.wall, self.push
        touched = self.shapes.wrench_at(p_m, v_m_s, out)  # zeroes `out` first
        if wall is not None:
            n0, n1, n2 = wall.normal
            w0, w1, w2 = wall.point_m
            depth = (w0 - p_m[0]) * n0 + (w1 - p_m[1]) * n1 + (w2 - p_m[2]) * n2
            if depth > 0.0:
                speed_out = v_m_s[0] * n0 + v_m_s[1] * n1 + v_m_s[2] * n2
                f = normal_force(wall.stiffness_n_m, wall.damping_n_s_m, depth, speed_out)
                out[0] += f * n0
                out[1] += f * n1
                out[2] += f * n2
                touched = touched or f > 0.0
        if push is not None:
            if self.now_s < push.until_s:
                out += np.asarray(push.wrench)
                touched = True
            else:
                self.push = None
        return touched

    def describe(self) -> dict[str, Any]:
        """For the control channel's status."""
        wall = self.wall
        return {
            "wall": None
            if wall is None
            else {
                "point_m": list(wall.point_m),
                "normal": list(wall.normal),
                "stiffness_n_m": wall.stiffness_n_m,
                "damping_n_s_m": wall.damping_n_s_m,
            },
            "push_active": self.push is not None and self.now_s < self.push.until_s,
            "shapes": len(self.shapes.shapes),
            "tool_radius_m": self.shapes.tool_radius_m,
        }
