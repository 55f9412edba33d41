"""The robot's dynamic model (Pinocchio) and its joint limits, as one immutable object.

`RobotModel` holds the Pinocchio `Model` (never mutated after load) and the limit vectors;
whoever computes with it makes its own `pin.Data` with `new_data()` (model/workspace split).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from orccadd.config.robot import RobotConfig, ToolConfig, WorkspaceConfig
from orccadd.config.schema import format_range
from orccadd.config.urdf import resolve_urdf
from orccadd.errors import ConfigError

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RobotModel:
    """Pinocchio model reduced to the configured joints, with limit vectors (SI units)."""

    model: pin.Model
    joint_names: tuple[str, ...]
    q_min_rad: FloatArray
    q_max_rad: FloatArray
    v_max_rad_s: FloatArray
    a_max_rad_s2: FloatArray
    j_max_rad_s3: FloatArray
    tau_max_nm: FloatArray
    home_rad: FloatArray
    # the tool's frame, added to `model` at load (`[tool]`: a URDF frame and an offset), its
    # limits, and the workspace it must stay in
    tool_frame_id: int = 0
    tool: ToolConfig = ToolConfig()
    workspace: WorkspaceConfig = WorkspaceConfig()

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def gravity_loaded(self, threshold_nm: float = 1e-3) -> bool:
        """Whether some joint must hold a load against gravity somewhere in its range (checked at
        home, at zero and at the range's corners of each joint): a stop without brakes drops it."""
        data = self.new_data()
        poses = [self.home_rad, np.clip(np.zeros(self.dof), self.q_min_rad, self.q_max_rad)]
        for j in range(self.dof):
            for bound in (
                self.q_min_rad[j],
                self.q_max_rad[j],
                0.5 * (self.q_min_rad[j] + self.q_max_rad[j]),
            ):
                q = self.home_rad.copy()
                q[j] = bound
                poses.append(q)
        return any(
            float(np.abs(pin.computeGeneralizedGravity(self.model, data, q)).max()) > threshold_nm
            for q in poses
        )

    def new_data(self) -> pin.Data:
        """A fresh Pinocchio workspace for this model (allocate once, outside ticks)."""
        return self.model.createData()

    @staticmethod
    def from_config(cfg: RobotConfig) -> RobotModel:
        """Load the URDF, lock unlisted joints, check names, order and manufacturer limits."""
        path = resolve_urdf(cfg)
        try:
            full = pin.buildModelFromUrdf(str(path))
        except Exception as e:  # pinocchio raises plain exceptions on malformed files
            raise ConfigError(
                cfg.source,
                "model.urdf",
                f"(={cfg.model.urdf!r}): {path} is not a URDF pinocchio can load: {e}",
            ) from None
        names = list(full.names)[1:]
        for i, name in enumerate(cfg.model.locked_joints):
            if name not in names:
                raise ConfigError(
                    cfg.source,
                    f"model.locked_joints[{i}]",
                    f"(={name!r}) is not a joint of {path.name} (joints: {', '.join(names)})",
                )
        q_ref = pin.neutral(full)
        for i, name in enumerate(cfg.model.locked_joints):
            if cfg.model.locked_positions:
                jid = full.getJointId(name)
                q_ref[full.joints[jid].idx_q] = cfg.model.locked_positions[i]
        lock_ids = [full.getJointId(n) for n in cfg.model.locked_joints]
        model = pin.buildReducedModel(full, lock_ids, q_ref) if lock_ids else full
        model_names = list(model.names)[1:]
        for i, j in enumerate(cfg.joints):
            if j.name not in model_names:
                raise ConfigError(
                    cfg.source,
                    f"joints[{i}].name",
                    f"(={j.name!r}) is not a joint of {path.name} (joints: {', '.join(model_names)})",
                )
        unlisted = [n for n in model_names if n not in cfg.joint_names]
        if unlisted:
            raise ConfigError(
                cfg.source,
                "joints",
                f"does not list {', '.join(unlisted)} of {path.name}: "
                "list them or name them in model.locked_joints",
            )
        for i, j in enumerate(cfg.joints):
            if model_names[i] != j.name:
                raise ConfigError(
                    cfg.source,
                    f"joints[{i}].name",
                    f"(={j.name!r}) is out of order: the model's order is {', '.join(model_names)}",
                )
            if model.joints[i + 1].nq != 1:
                raise ConfigError(cfg.source, f"joints[{i}].name", f"(={j.name!r}) is not a one-axis joint")
        _check_against_urdf(cfg, model)
        if cfg.model.armature_kg_m2:
            model.armature = np.array(cfg.model.armature_kg_m2, dtype=np.float64)
        model.gravity = pin.Motion(np.array([0.0, 0.0, -9.81, 0.0, 0.0, 0.0]))
        tool_frame_id = _add_tool_frame(cfg, model, path.name)
        return RobotModel(
            model=model,
            joint_names=cfg.joint_names,
            q_min_rad=arr([j.position_min_rad for j in cfg.joints]),
            q_max_rad=arr([j.position_max_rad for j in cfg.joints]),
            v_max_rad_s=arr([j.max_velocity_rad_s for j in cfg.joints]),
            a_max_rad_s2=arr([j.max_acceleration_rad_s2 for j in cfg.joints]),
            j_max_rad_s3=arr([j.max_jerk_rad_s3 for j in cfg.joints]),
            tau_max_nm=arr([j.max_torque_nm for j in cfg.joints]),
            home_rad=arr([j.home_rad for j in cfg.joints]),
            tool_frame_id=tool_frame_id,
            tool=cfg.tool,
            workspace=cfg.workspace,
        )


def arr(values: list[float]) -> FloatArray:
    return np.array(values, dtype=np.float64)


def _check_against_urdf(cfg: RobotConfig, model: pin.Model) -> None:
    """The config may only narrow the manufacturer's limits written in the URDF."""
    for i, j in enumerate(cfg.joints):
        lo, hi = float(model.lowerPositionLimit[i]), float(model.upperPositionLimit[i])
        vmax, tmax = float(model.velocityLimit[i]), float(model.effortLimit[i])
        checks = []
        if lo < hi:
            checks += [("position_min_rad", lo, hi, False), ("position_max_rad", lo, hi, False)]
        if vmax > 0:
            checks.append(("max_velocity_rad_s", 0.0, vmax, True))
        if tmax > 0:
            checks.append(("max_torque_nm", 0.0, tmax, True))
        for attr, low, high, open_lo in checks:
            val = getattr(j, attr)
            if not low - 1e-9 <= val <= high + 1e-9:
                raise ConfigError(
                    cfg.source,
                    f"joints[{i}].{attr}",
                    f"(={val!r}) must be in {format_range(low, high, open_lo, False)} "
                    f"(URDF limit of {j.name})",
                )


TOOL_FRAME = "orccadd_tool"


def _add_tool_frame(cfg: RobotConfig, model: pin.Model, urdf_name: str) -> int:
    """Add the tool's frame (`[tool]`) to `model`: its id. The URDF frame it is fixed to must
    move with the configured joints (a frame of the base would make every Cartesian task a
    no-op)."""
    name = cfg.tool.frame
    if name:
        if not model.existFrame(name):
            frames = ", ".join(f.name for f in model.frames if f.name != "universe")
            raise ConfigError(
                cfg.source, "tool.frame", f"(={name!r}) is not a frame of {urdf_name} (frames: {frames})"
            )
        parent_id = model.getFrameId(name)
    else:  # the link the last joint moves
        last = model.njoints - 1
        bodies = [
            i for i, f in enumerate(model.frames) if f.parentJoint == last and f.type == pin.FrameType.BODY
        ]
        parent_id = bodies[0]
    parent = model.frames[parent_id]
    if parent.parentJoint == 0:
        raise ConfigError(
            cfg.source, "tool.frame", f"(={name!r}) is fixed to the base: no joint moves it, so no task can"
        )
    offset = pin.SE3(
        pin.rpy.rpyToMatrix(*cfg.tool.offset_rpy_rad), np.array(cfg.tool.offset_m, dtype=np.float64)
    )
    frame = pin.Frame(
        TOOL_FRAME, parent.parentJoint, parent_id, parent.placement * offset, pin.FrameType.OP_FRAME
    )
    return int(model.addFrame(frame, False))
