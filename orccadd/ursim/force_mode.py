"""Force mode, freedrive and teach mode: an admittance on the TCP, one controller cycle at a time.

URScript's `force_mode(task_frame, selection_vector, wrench, type, limits)`: along/about the
compliant axes of the task frame (selection 1) the robot moves so that the wrench it applies to
its environment becomes `wrench`; the other axes keep the pose the program set. Modelled as a
mass-damper on each compliant axis of the task frame, driven by the force error:

    a  = −F_measured          (the wrench the robot applies: the sensor reads the reaction)
    v̇  = gain·(wrench − a)/M − D·v,      D = damping · D_FULL_1_S
    |v| ≤ limit               (limits: the compliant axes' speed limits, m/s and rad/s)

with `gain` and `damping` from force_mode_set_gain_scaling / force_mode_set_damping (URScript:
damping 1 "decelerates quickly if no force is present", 0 "maintains the speed"). In free space
a wrench accelerates the tool to its speed limit until it meets something; against a wall of
stiffness k the force settles at `wrench` (natural frequency √(gain·k/M)). The non-compliant
axes are servoed back onto the pose at the start, v = K_HOLD·(pose error). The TCP twist
(task frame → base) becomes joint velocities by damped least squares on the TCP Jacobian at the
target, q̇ = Jᵀ(JJᵀ + λ²I)⁻¹V, scaled into the joints' speed limits, and the target integrates
them: the arm's joint servo follows as it follows any target.

Freedrive (freedrive_mode(free_axes, feature), teach_mode) is the same admittance with no
wrench to apply on the free axes of the feature frame, a heavier mass and strong damping: the
tool moves while pushed and stops when let go, the other axes hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import pinocchio as pin

from orccadd.state import FloatArray
from orccadd.ursim.motion import Motion, Target
from orccadd.ursim.task_frame import task_rotation

MASS_KG = 1.0  # the admittance's virtual mass on translational axes
INERTIA_KG_M2 = 0.01  # ... and on rotational axes
D_FULL_1_S = 1000.0  # damping 1 → 1000 /s: stops within a few cycles
K_HOLD_1_S = 20.0  # non-compliant axes back to their pose
DLS_LAMBDA = 0.02  # damped least squares near singularities
JOINT_SPEED_SHARE = 0.9  # of each joint's speed limit
# limits of the controller's safety configuration (e-Series defaults, "Normal" mode)
TOOL_FORCE_LIMIT_N = 150.0
TOOL_SPEED_LIMIT_M_S = 1.5
ROTATION_SPEED_LIMIT_RAD_S = math.pi  # the joints' speed limit
# freedrive: heavier, damped, with its own speed caps
FREEDRIVE_MASS_KG = 4.0
FREEDRIVE_INERTIA_KG_M2 = 0.1
FREEDRIVE_DAMPING_1_S = 20.0
FREEDRIVE_LIMITS = (0.25, 0.25, 0.25, 1.0, 1.0, 1.0)


@dataclass(frozen=True)
class ForceModeArgs:
    """force_mode's arguments as ur_rtde's script reads them (float registers 0-5 task frame,
    6-11 wrench, 12-17 limits; int register 1 type, 2-7 selection vector)."""

    task_frame: tuple[float, ...]
    selection: tuple[int, ...]
    wrench: tuple[float, ...]
    frame_type: int
    limits: tuple[float, ...]


def force_mode_error(a: ForceModeArgs) -> str:
    """Why the controller refuses these arguments ('' if it takes them): a runtime error."""
    if a.frame_type not in (1, 2, 3):
        return f"force_mode: type (={a.frame_type}) must be 1, 2 or 3"
    if any(s not in (0, 1) for s in a.selection):
        return f"force_mode: selection_vector (={list(a.selection)}) must hold 0 or 1"
    if not all(math.isfinite(v) for v in (*a.task_frame, *a.wrench, *a.limits)):
        return "force_mode: task_frame, wrench and limits must be finite"
    if any(v < 0.0 for v in a.limits):
        return f"force_mode: limits (={list(a.limits)}) must be >= 0"
    force = math.sqrt(sum(a.wrench[i] ** 2 for i in range(3) if a.selection[i]))
    if force > TOOL_FORCE_LIMIT_N:
        limit = TOOL_FORCE_LIMIT_N
        return f"force_mode: wrench force {force:.1f} N exceeds the tool force limit ({limit:g} N)"
    for i in range(6):
        cap = TOOL_SPEED_LIMIT_M_S if i < 3 else ROTATION_SPEED_LIMIT_RAD_S
        if a.selection[i] and a.limits[i] > cap:
            unit = "m/s" if i < 3 else "rad/s"
            return f"force_mode: speed limit {a.limits[i]:g} {unit} of axis {i} exceeds {cap:g} {unit}"
    return ""


class Kinematics(Protocol):
    """What the admittance needs of the arm (`arm.UrArm`)."""

    v_max_rad_s: FloatArray

    def tcp(self, q: FloatArray) -> pin.SE3: ...
    def tcp_jacobian(self, q: FloatArray, out: FloatArray) -> FloatArray: ...


class Admittance(Motion):
    """Force mode or freedrive (`name`), stepped by the controller every cycle; `force` and
    `tcp_speed` are the controller's arrays of the measured wrench (actual_TCP_force) and the
    TCP's speed, read each step."""

    def __init__(
        self,
        name: str,
        arm: Kinematics,
        force: FloatArray,
        tcp_speed: FloatArray,
        args: ForceModeArgs,
        gain: float,
        damping_1_s: float,
        mass: tuple[float, float] = (MASS_KG, INERTIA_KG_M2),
    ) -> None:
        self.name = name
        self.arm, self.force, self.tcp_speed = arm, force, tcp_speed
        self.args = args
        self.gain, self.damping_1_s = gain, damping_1_s
        self.mass = np.array([mass[0]] * 3 + [mass[1]] * 3)
        self.v_task = np.zeros(6)  # the compliant axes' speeds, task frame
        self._ref: pin.SE3 | None = None  # the pose the non-compliant axes keep
        self._jac = np.zeros((6, len(arm.v_max_rad_s)))

    def update(self, args: ForceModeArgs) -> None:
        """New arguments while running (the script's force thread re-reads them each cycle)."""
        self.args = args

    def step(self, tgt: Target, h_s: float) -> bool:
        a = self.args
        pose = self.arm.tcp(tgt.q)
        if self._ref is None:
            self._ref = pose.copy()
        r = task_rotation(np.asarray(a.task_frame), a.frame_type, pose.translation, self.tcp_speed[0:3])
        applied = np.concatenate((r.T @ -self.force[0:3], r.T @ -self.force[3:6]))
        ref = self._ref
        err_pose = np.concatenate(
            (r.T @ (ref.translation - pose.translation), r.T @ pin.log3(ref.rotation @ pose.rotation.T))
        )
        sel = np.asarray(a.selection, dtype=bool)
        acc = self.gain * (np.asarray(a.wrench) - applied) / self.mass - self.damping_1_s * self.v_task
        v = self.v_task
        v += acc * h_s
        np.clip(v, -np.asarray(a.limits), np.asarray(a.limits), out=v)
        v[~sel] = 0.0
        v_task = np.where(sel, v, K_HOLD_1_S * err_pose)
        twist = np.concatenate((r @ v_task[0:3], r @ v_task[3:6]))
        jac = self.arm.tcp_jacobian(tgt.q, self._jac)
        qd = jac.T @ np.linalg.solve(jac @ jac.T + DLS_LAMBDA**2 * np.eye(6), twist)
        over = float(np.max(np.abs(qd) / (JOINT_SPEED_SHARE * self.arm.v_max_rad_s)))
        if over > 1.0:
            qd /= over
            v /= over
        qd0 = tgt.qd.copy()
        tgt.qd[:] = qd
        tgt.qdd[:] = (qd - qd0) / h_s
        tgt.q += 0.5 * (qd0 + qd) * h_s
        return False


def freedrive_args(free_axes: tuple[int, ...], feature: tuple[float, ...]) -> ForceModeArgs:
    """Freedrive as an admittance: the free axes of the feature frame compliant, no wrench."""
    return ForceModeArgs(feature, tuple(1 if f else 0 for f in free_axes), (0.0,) * 6, 2, FREEDRIVE_LIMITS)


def freedrive_status(arm: Kinematics, q: FloatArray) -> int:
    """get_freedrive_status(): 0 normal, 1 near a singularity, 2 too close to one (high
    resistance), from the TCP Jacobian's smallest singular value."""
    sigma = float(np.linalg.svd(arm.tcp_jacobian(q, np.zeros((6, len(q)))), compute_uv=False)[-1])
    return 2 if sigma < 0.01 else 1 if sigma < 0.03 else 0
