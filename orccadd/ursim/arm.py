"""The arm behind the simulated controller: rigid-body dynamics and kinematics from the URDF.

The dynamics are `orccadd.physres.sim.SimulatedArm`'s (Pinocchio ABA in fixed sub-steps,
friction, brakes as extra Coulomb torque) in position mode: its joint servo (PD with gravity
feed-forward, velocity feed-forward from the target's steps) is the UR's inner joint loop, so
`actual_q` follows `target_q` with a servo's lag and the joint torques are those of the arm
holding itself up. Brakes engaged = the resource inactive (motors off), released = active.

Poses are UR's: [x, y, z, rx, ry, rz] in metres and a rotation vector (radians), of the tool
flange (`tool0`) composed with the TCP offset, in the base frame.

The world (`world.World`: a wall, a push) acts on the dynamics through the TCP's Jacobian,
τ_ext = J_tcpᵀ·W at every sub-step (`ArmDynamics.external`); the payload (`set_payload`) is a point
mass on the flange's link, in the model the dynamics and the gravity compensation share.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.errors import ConfigError
from orccadd.model import RobotModel
from orccadd.physres.sim import SimSettings, SimulatedArm, load_sim_settings
from orccadd.state import FloatArray
from orccadd.types import CommandMode, Lifecycle
from orccadd.ursim.world import World

TOOL_FRAME = "tool0"
CURRENT_AT_MAX_TORQUE_A = 12.0  # the simulator's motor model: a joint's max torque at 12 A
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def pose_to_se3(pose: Any) -> pin.SE3:
    """A UR pose [x, y, z, rx, ry, rz] as a transform."""
    p = np.asarray(pose, dtype=np.float64)
    return pin.SE3(pin.exp3(p[3:6]), p[0:3].copy())


def rotation_vector(r: FloatArray) -> tuple[float, float, float]:
    """The rotation vector (axis × angle, angle in [0, π]) of a rotation matrix; in plain floats
    (several times faster than `pin.log3` for one matrix)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r.tolist()
    c = max(-1.0, min(1.0, 0.5 * (r00 + r11 + r22 - 1.0)))
    angle = math.acos(c)
    x, y, z = r21 - r12, r02 - r20, r10 - r01
    s = math.sqrt(x * x + y * y + z * z)  # = 2 sin(angle)
    if s > 1e-6:
        k = angle / s
        return x * k, y * k, z * k
    if c > 0.0:  # near the identity: angle ≈ s / 2
        return 0.5 * x, 0.5 * y, 0.5 * z
    # near π: R ≈ 2 u uᵀ − I gives the axis: |u_i| from the diagonal, the rest from the largest
    # one's row; the skew part (2 sin(angle) u) still tells the sign where it is not zero
    u = [math.sqrt(max(0.0, 0.5 * (d + 1.0))) for d in (r00, r11, r22)]
    i = max(range(3), key=lambda k: u[k])
    sym = {(0, 1): (r01 + r10) * 0.25, (0, 2): (r02 + r20) * 0.25, (1, 2): (r12 + r21) * 0.25}
    for j in range(3):
        if j != i:
            u[j] = sym[min(i, j), max(i, j)] / u[i]
    if (x, y, z)[i] < 0.0:
        u = [-c for c in u]
    return u[0] * angle, u[1] * angle, u[2] * angle


def se3_to_pose(m: pin.SE3, out: FloatArray) -> FloatArray:
    """A transform as a UR pose, written into `out`."""
    out[0:3] = m.translation
    out[3:6] = rotation_vector(m.rotation)
    return out


class UrArm:
    """Dynamics (position-servoed) and kinematics of the arm, stepped by the controller."""

    def __init__(
        self, cfg: RobotConfig, period_s: float, sim_settings: dict[str, Any], settings_file: str = ""
    ) -> None:
        """`sim_settings`: the `sim` backend's settings for the dynamics (friction, initial_q_rad,
        ...), read from `settings_file` (named in errors)."""
        raw = {"substep_s": min(0.001, period_s), **sim_settings}
        cfg = replace(cfg, control_period_s=period_s)
        settings = load_sim_settings(SimSettings, raw, cfg, settings_file or cfg.source)
        if settings.world_planes or settings.world_holes:
            key = "world_planes" if settings.world_planes else "world_holes"
            raise ConfigError(
                settings_file or cfg.source,
                key,
                "is the simulated arm's: the UR simulator's world is set through its control channel (wall)",
            )
        if settings.camera is not None:
            raise ConfigError(
                settings_file or cfg.source, "camera", "is the simulated arm's: the UR simulator has none"
            )
        cfg = replace(
            cfg,
            resource=replace(cfg.resource, backend="sim", settings=raw),
            backend_settings=settings,
        )
        self.model = RobotModel.from_config(cfg)
        self.sim = SimulatedArm(cfg, self.model)
        self.sim.configure()
        self.sim.state.q_rad[:] = self.sim.q  # measured before the first cycle: where it rests
        self.dof = self.model.dof
        self.q_min_rad, self.q_max_rad = self.model.q_min_rad, self.model.q_max_rad
        self.v_max_rad_s, self.a_max_rad_s2 = self.model.v_max_rad_s, self.model.a_max_rad_s2
        self._pin = self.model.model
        self._data = self.model.new_data()
        names = [f.name for f in self._pin.frames]
        self._tool = self._pin.getFrameId(TOOL_FRAME) if TOOL_FRAME in names else len(names) - 1
        self._elbow_joint = min(3, self._pin.njoints - 1)
        self._amps_per_nm = CURRENT_AT_MAX_TORQUE_A / self.model.tau_max_nm
        self.tcp_offset = pin.SE3.Identity()
        self._no_offset = True
        self._payload_joint = self._pin.frames[self._tool].parentJoint
        self._payload_at = self._pin.frames[self._tool].placement  # tool0 in its joint's frame
        self._bare_inertia = self._pin.inertias[self._payload_joint].copy()
        self.payload_kg = 0.0
        self.world = World()
        self._ext_data = self.model.new_data()  # the sub-steps' kinematics (not the cycle's)
        self._ext_jac = np.zeros((6, self.dof))
        self._ext_wrench = np.zeros(6)
        self.sim.arm.external = self._external_torque

    def set_tcp_offset(self, pose: Any) -> None:
        """The TCP relative to the flange (a UR pose), as `set_tcp` sets it."""
        self.tcp_offset = pose_to_se3(pose)
        self._no_offset = not np.any(np.asarray(pose, dtype=np.float64))

    def set_payload(self, mass_kg: float, cog_m: Any) -> None:
        """The payload on the flange: a point mass at `cog_m` (flange frame), part of the model
        the dynamics integrate and the controller's gravity compensation uses."""
        extra = pin.Inertia(float(mass_kg), np.asarray(cog_m, dtype=np.float64), np.zeros((3, 3)))
        self._pin.inertias[self._payload_joint] = self._bare_inertia + self._payload_at.act(extra)
        self.payload_kg = float(mass_kg)

    # ---- brakes ---------------------------------------------------------------------------
    @property
    def brakes_released(self) -> bool:
        return self.sim.lifecycle is Lifecycle.ACTIVE

    def release_brakes(self) -> None:
        """Motors on, holding where the arm is (position mode)."""
        if not self.brakes_released:
            self.sim.activate(CommandMode.POSITION)

    def engage_brakes(self) -> None:
        """Motors off, brakes on."""
        if self.brakes_released:
            self.sim.deactivate()

    # ---- cycle ----------------------------------------------------------------------------
    def sample(self, t_s: float) -> None:
        """Integrate the dynamics up to `t_s` with the last target held."""
        self.sim.read(t_s)

    def command(self, t_s: float, q_target_rad: FloatArray) -> None:
        """The joint servo's next target (only while the brakes are released)."""
        if self.brakes_released:
            if self.sim.mode is not CommandMode.POSITION:  # back from direct torque: held here
                self.sim.switch_mode(CommandMode.POSITION)
            self.sim.write(t_s, q_target_rad)

    def apply_torque(self, t_s: float, tau_nm: FloatArray) -> None:
        """Direct torque until the next cycle: `tau_nm` on top of the arm's gravity at the cycle's
        q (the controller compensates gravity; friction is the arm's own, uncompensated: ur_rtde
        1.6's script passes zero friction scales to `direct_torque`)."""
        if not self.brakes_released:
            return
        if self.sim.mode is not CommandMode.TORQUE:
            self.sim.switch_mode(CommandMode.TORQUE)
        gravity = pin.computeGeneralizedGravity(self._pin, self._data, self.q_rad)
        self.sim.write(t_s, tau_nm + gravity)

    @property
    def q_rad(self) -> FloatArray:
        return self.sim.state.q_rad

    @property
    def dq_rad_s(self) -> FloatArray:
        return self.sim.state.dq_rad_s

    @property
    def tau_nm(self) -> FloatArray:
        return self.sim.state.tau_nm

    def current_a(self, tau_nm: FloatArray, out: FloatArray) -> FloatArray:
        np.multiply(tau_nm, self._amps_per_nm, out=out)
        return out

    # ---- kinematics and dynamics ----------------------------------------------------------
    def tcp(self, q: FloatArray) -> pin.SE3:
        """The TCP's transform at `q` (flange composed with the TCP offset)."""
        pin.framesForwardKinematics(self._pin, self._data, q)
        flange: pin.SE3 = self._data.oMf[self._tool]
        return flange * self.tcp_offset

    def tcp_pose(self, q: FloatArray, out: FloatArray) -> FloatArray:
        return se3_to_pose(self.tcp(q), out)

    def flange_pose(self, q: FloatArray, tcp_offset: Any, out: FloatArray) -> FloatArray:
        """FK with another TCP offset (a UR pose), as `get_forward_kin(q, tcp)` does."""
        pin.framesForwardKinematics(self._pin, self._data, q)
        return se3_to_pose(self._data.oMf[self._tool] * pose_to_se3(tcp_offset), out)

    def kinematics(
        self,
        q: FloatArray,
        dq: FloatArray,
        pose: FloatArray,
        speed: FloatArray,
        elbow: tuple[FloatArray, FloatArray] | None = None,
    ) -> None:
        """One kinematics pass at (`q`, `dq`): the TCP's pose and its speed [v, w] in the base
        frame, and the elbow's position and linear velocity if `elbow` is given."""
        m, d = self._pin, self._data
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacement(m, d, self._tool)
        flange = d.oMf[self._tool]
        se3_to_pose(flange if self._no_offset else flange * self.tcp_offset, pose)
        v = pin.getFrameJacobian(m, d, self._tool, LWA) @ dq
        # the TCP's linear speed: the flange's plus w × (the offset in the base frame)
        r = flange.rotation @ self.tcp_offset.translation
        wx, wy, wz = v[3], v[4], v[5]
        speed[0] = v[0] + wy * r[2] - wz * r[1]
        speed[1] = v[1] + wz * r[0] - wx * r[2]
        speed[2] = v[2] + wx * r[1] - wy * r[0]
        speed[3:6] = v[3:6]
        if elbow is not None:
            j = self._elbow_joint
            elbow[0][:] = d.oMi[j].translation
            elbow[1][:] = pin.getJointJacobian(m, d, j, LWA)[0:3] @ dq

    def tcp_jacobian(self, q: FloatArray, out: FloatArray) -> FloatArray:
        """The TCP's Jacobian at `q` (6×n, base frame: rows vx vy vz wx wy wz), into `out`."""
        return self._tcp_jacobian(q, self._data, out)

    def _tcp_jacobian(self, q: FloatArray, d: Any, out: FloatArray) -> FloatArray:
        m = self._pin
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacement(m, d, self._tool)
        out[:] = pin.getFrameJacobian(m, d, self._tool, LWA)
        if not self._no_offset:  # v_tcp = v_flange + w × r = v_flange − [r]× w
            r = d.oMf[self._tool].rotation @ self.tcp_offset.translation
            out[0:3] -= pin.skew(r) @ out[3:6]
        return out

    def tcp_position(self) -> FloatArray:
        """The TCP's position after the last `tcp_jacobian` (base frame, m)."""
        m: pin.SE3 = self._data.oMf[self._tool] * self.tcp_offset
        return np.asarray(m.translation)

    def external_wrench(self, q: FloatArray, dq: FloatArray, out: FloatArray) -> bool:
        """The world's wrench on the TCP at (q, dq) into `out` (base frame, N and N·m about the
        TCP); False when nothing touches the tool."""
        if self.world.empty:
            out[:] = 0.0
            return False
        jac = self._tcp_jacobian(q, self._ext_data, self._ext_jac)
        p = (self._ext_data.oMf[self._tool] * self.tcp_offset).translation
        return self.world.wrench_at(p, jac[0:3] @ dq, out)

    def _external_torque(self, q: FloatArray, dq: FloatArray) -> FloatArray | None:
        if not self.external_wrench(q, dq, self._ext_wrench):
            return None
        tau: FloatArray = self._ext_jac.T @ self._ext_wrench
        return tau

    def inverse_dynamics(self, q: FloatArray, dq: FloatArray, ddq: FloatArray, out: FloatArray) -> FloatArray:
        out[:] = pin.rnea(self._pin, self._data, q, dq, ddq)
        return out
