"""Operational-space computed torque (Khatib, 1987) for torque-controlled arms: the tool's pose
error, not the joints', makes the torques.

Each tick, with M the joint-space inertia, h the Coriolis, centrifugal and gravity torques, J the
tool's frame Jacobian (base axes at the tool's point) and J̇·q̇ its drift acceleration:

    e  = (p_des − p, log3(R_des·Rᵀ)),   ė = twist_des − J·q̇
    a  = ẍ_des + kd·ė + kp·e + ki·∫e − J̇·q̇             the tool's wanted acceleration
    Λ  = (J·M⁻¹·Jᵀ + damping²·I)⁻¹                     its inertia (damped near singularities)
    τ  = Jᵀ·Λ·a + h + (I − Jᵀ·J̄ᵀ)·M·(kp_null·(q₀ − q) − kd_null·q̇)

with J̄ = M⁻¹·Jᵀ·Λ the dynamically consistent inverse and q₀ the joints when the task started:
a redundant arm (a Panda's seventh joint) keeps its posture in the null space, which the tool
does not feel. ẍ_des is the desired twist's finite difference; the integral (`ki`, its
integral clamped to ±`integral_limit` m·s or rad·s, zero at the start) takes out the steady
error the model leaves (friction, a payload). On a non-redundant arm away from
singularities the null-space term vanishes; the error dynamics are ë + kd·ė + kp·e = 0 per axis
of the tool.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.kinematics import WORLD_ALIGNED, ToolKinematics, task_error
from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.modules.cartesian import TWIST_UNIT
from orccadd.state import JointState


@register("operational_space")
class OperationalSpace(KernelModule):
    """Operational-space computed torque (see the module's doc): measured q, dq and the desired
    pose and twist in, joint torques out."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.add_input("q", (n,), "rad")
        self.add_input("dq", (n,), "rad/s")
        self.add_input("position_des_m", (3,), "m")
        self.add_input("orientation_des", (4,), "1")
        self.add_input("twist_des", (6,), TWIST_UNIT)
        self.add_output("tau", (n,), "N.m")
        self.kp = self.add_parameter("kp", 900.0, bounds=(0.0, 1e5), unit="1/s^2", tunable=True)
        self.kd = self.add_parameter("kd", 60.0, bounds=(0.0, 1e3), unit="1/s", tunable=True)
        self.kp_null = self.add_parameter("kp_null", 100.0, bounds=(0.0, 1e4), unit="1/s^2", tunable=True)
        self.kd_null = self.add_parameter("kd_null", 20.0, bounds=(0.0, 1e3), unit="1/s", tunable=True)
        self.ki = self.add_parameter("ki", 0.0, bounds=(0.0, 1e6), unit="1/s^3", tunable=True)
        self.i_max = self.add_parameter("integral_limit", 0.005, bounds=(0.0, 1.0), unit="m.s", tunable=True)
        self.damping = self.add_parameter("damping", 0.01, bounds=(0.0, 1.0), unit="1", tunable=True)
        self._e_sum = np.zeros(6)  # ∫e, the integral term's
        self._kin = ToolKinematics(ctx.model)
        self._model, self._data = ctx.model.model, ctx.model.new_data()
        self._q, self._dq = np.zeros(n), np.zeros(n)
        self._q0 = np.zeros(n)
        self._twist_prev: np.ndarray | None = None
        self._eye_n = np.eye(n)
        self._eye6 = np.eye(6)

    def start(self, state: JointState) -> None:
        self._q0 = state.q_rad.copy()
        self._twist_prev = None
        self._e_sum = np.zeros(6)

    def kernel(self) -> Kernel:
        model, data, kin, qa, dqa = self._model, self._data, self._kin, self._q, self._dq
        dt, frame = self.ctx.period_s, self._kin.frame_id

        def operational_space(
            t_s: float,
            q: list[float],
            dq: list[float],
            position_des_m: list[float],
            orientation_des: list[float],
            twist_des: list[float],
        ) -> tuple[list[float]]:
            qa[:], dqa[:] = q, dq
            pose = kin.pose_and_jacobian(qa)
            j = kin.jacobian
            m = pin.crba(model, data, qa)
            m = np.triu(m) + np.triu(m, 1).T  # crba fills the upper triangle
            h = pin.nonLinearEffects(model, data, qa, dqa)
            pin.forwardKinematics(model, data, qa, dqa, np.zeros_like(qa))
            drift = pin.getFrameClassicalAcceleration(model, data, frame, WORLD_ALIGNED).vector
            v_des = np.asarray(twist_des)
            acc_des = np.zeros(6) if self._twist_prev is None else (v_des - self._twist_prev) / dt
            self._twist_prev = v_des
            e = np.array(task_error(pose, position_des_m, orientation_des))
            de = v_des - j @ dqa
            a = acc_des + float(self.kd.value) * de + float(self.kp.value) * e - drift
            ki = float(self.ki.value)
            if ki > 0.0:
                limit = float(self.i_max.value)
                self._e_sum = np.clip(self._e_sum + e * dt, -limit, limit)
                a += ki * self._e_sum
            m_inv = np.linalg.inv(m)
            lam = np.linalg.inv(j @ m_inv @ j.T + float(self.damping.value) ** 2 * self._eye6)
            tau = j.T @ (lam @ a) + h
            posture = m @ (float(self.kp_null.value) * (self._q0 - qa) - float(self.kd_null.value) * dqa)
            j_bar = m_inv @ j.T @ lam
            tau += (self._eye_n - j.T @ j_bar.T) @ posture
            return (tau.tolist(),)

        return operational_space
