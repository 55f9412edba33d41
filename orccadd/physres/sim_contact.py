"""The contact world on the simulated arm's tool, and its force/torque sensor.

`ToolContact` puts a `contact.ContactWorld` (planes, holes: the model and its equations are in
`orccadd.physres.contact`) on the tool point of the robot config's `[tool]`
(`RobotModel.tool_frame_id`): at every sub-step of the dynamics, the world's wrench W at the
tool point (base axes) enters as the joint torques τ_ext = Jᵀ·W, J the tool's frame Jacobian
(`orccadd.kinematics.ToolKinematics`: LOCAL_WORLD_ALIGNED, linear rows first); at every read,
the simulated F/T sensor measures W at the arm's state (plus white Gaussian noise, seeded, when
configured): the resource's `wrench` signal.

The world is declared in the `sim` backend's `[resource.settings]` (`world_planes`,
`world_holes`, `tool_radius_m`) and changed at run time by `change_world` (the plant process's
control channel: `plane`, `hole`, `clear_world`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from orccadd.config.schema import field
from orccadd.errors import ConfigError
from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.physres.contact import (
    ContactWorld,
    Shape,
    ShapeError,
    hole_from_params,
    only,
    plane_from_params,
)
from orccadd.physres.description import Signal
from orccadd.state import FloatArray

INF = math.inf
WRENCH = Signal(
    "wrench",
    6,
    "N|N.m",
    "the force and torque the world exerts on the tool, at the tool point ([tool]), base axes: "
    "measured by the simulated F/T sensor",
)
# what the control channel changes: a plane added, a hole added, every shape removed
WORLD_CHANGES = ("plane", "hole", "clear_world")


@dataclass(frozen=True)
class PlaneSettings:
    """One entry of `world_planes` (see `contact.Plane`)."""

    point_m: tuple[float, ...] = field()
    normal: tuple[float, ...] = field()
    stiffness_n_m: float = field(bounds=(0.0, INF), open_lo=True, open_hi=True)
    damping_n_s_m: float = field(default=100.0, bounds=(0.0, INF), open_hi=True)
    friction: float = field(default=0.0, bounds=(0.0, INF), open_hi=True)
    viscous_friction_n_s_m: float = field(default=0.0, bounds=(0.0, INF), open_hi=True)


@dataclass(frozen=True)
class HoleSettings:
    """One entry of `world_holes` (see `contact.Hole`); no `depth_m`: a hole through."""

    center_m: tuple[float, ...] = field()
    normal: tuple[float, ...] = field()
    radius_m: float = field(bounds=(0.0, INF), open_lo=True, open_hi=True)
    stiffness_n_m: float = field(bounds=(0.0, INF), open_lo=True, open_hi=True)
    depth_m: float | None = field(default=None, bounds=(0.0, INF), open_lo=True, open_hi=True)
    damping_n_s_m: float = field(default=100.0, bounds=(0.0, INF), open_hi=True)
    friction: float = field(default=0.0, bounds=(0.0, INF), open_hi=True)
    viscous_friction_n_s_m: float = field(default=0.0, bounds=(0.0, INF), open_hi=True)


def shapes_from_settings(
    planes: tuple[PlaneSettings, ...], holes: tuple[HoleSettings, ...], file: str
) -> tuple[Shape, ...]:
    """The shapes a config declares; `ConfigError` naming the file, the key and the value."""
    shapes: list[Shape] = []
    tables: tuple[tuple[str, tuple[Any, ...], Any], ...] = (
        ("world_planes", planes, plane_from_params),
        ("world_holes", holes, hole_from_params),
    )
    for key, entries, make in tables:
        for i, entry in enumerate(entries):
            params = {k: v for k, v in dataclasses.asdict(entry).items() if v is not None}
            try:
                shapes.append(make(params))
            except ShapeError as e:
                raise ConfigError(file, f"resource.settings.{key}[{i}].{e.key}", e.detail) from None
    return tuple(shapes)


def change_world(world: ContactWorld, what: str, params: dict[str, Any]) -> None:
    """One of `WORLD_CHANGES` with its parameters (`ValueError` naming what is wrong)."""
    if what == "plane":
        shape: Shape = _shape(plane_from_params, params, what)
    elif what == "hole":
        shape = _shape(hole_from_params, params, what)
    elif what == "clear_world":
        only(params, (), what)
        world.clear()
        return
    else:
        raise ValueError(f"unknown fault {what!r} (faults: {', '.join(WORLD_CHANGES)})")
    world.add(shape)


def _shape(make: Any, params: dict[str, Any], what: str) -> Shape:
    try:
        shape: Shape = make(params)
    except ShapeError as e:
        raise ValueError(f"{what}: {e}") from None
    return shape


class ToolContact:
    """The world's torques on the arm (`torque`, `ArmDynamics.external`, every sub-step) and the
    sensor's reading (`measure`, every read). No allocation of its own per call (Pinocchio's
    Jacobian aside); nothing computed while the world is empty."""

    def __init__(
        self,
        model: RobotModel,
        world: ContactWorld,
        noise_force_n: float = 0.0,
        noise_torque_nm: float = 0.0,
        seed: int = 0,
    ) -> None:
        self.world = world
        self._kin = ToolKinematics(model)
        self._v = np.zeros(3)
        self._wrench = np.zeros(6)
        self._tau = np.zeros(model.dof)
        self._noise_std = np.array([noise_force_n] * 3 + [noise_torque_nm] * 3)
        self._noisy = bool(noise_force_n or noise_torque_nm)
        self._noise = np.zeros(6)
        self._rng = np.random.default_rng([seed, 6])  # a stream of its own beside the joints' noise

    def wrench_at(self, q: FloatArray, dq: FloatArray, out: FloatArray) -> bool:
        """The world's wrench on the tool at (q, dq) into `out`; False (zero) when none."""
        if not self.world.shapes:
            out[:] = 0.0
            return False
        kin = self._kin
        pose = kin.pose_and_jacobian(q)
        np.dot(kin.jacobian[0:3], dq, out=self._v)
        return self.world.wrench_at(pose.translation, self._v, out)

    def torque(self, q: FloatArray, dq: FloatArray) -> FloatArray | None:
        """τ_ext = Jᵀ·W at (q, dq) (the dynamics' external torque), None when nothing touches."""
        if not self.wrench_at(q, dq, self._wrench):
            return None
        np.dot(self._kin.jacobian.T, self._wrench, out=self._tau)
        return self._tau

    def measure(self, q: FloatArray, dq: FloatArray, out: FloatArray) -> None:
        """The F/T sensor's reading at (q, dq) into `out` (the wrench, plus noise if configured)."""
        self.wrench_at(q, dq, out)
        if self._noisy:
            self._rng.standard_normal(out=self._noise)
            self._noise *= self._noise_std
            out += self._noise
