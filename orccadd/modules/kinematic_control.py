"""Kinematic control of the tool: joint references that make the tool follow a desired pose.

`resolved_rate` is closed-loop inverse kinematics (Siciliano's CLIK) on a joint reference of its
own: each tick

    e  = (p_des − p(q_ref), log3(R_des·R(q_ref)ᵀ))            the task error
    dq = J⁺(q_ref)·(twist_des + gain·e) + (I − J⁺J)·dq_centre   the task, then the null space
    q_ref += dq·dt

with J⁺ the damped least-squares inverse: no damping while J's smallest singular value is above
`singular_value_threshold`, then growing to `max_damping` at a singularity (Nakamura's and
Chiaverini's variable damping), so that the joints never run away near one; `dq_centre` pulls the
joints toward the middle of their ranges (gain `joint_centering_gain`), which the task does not
feel. `dq` is scaled down (its direction kept) to `velocity_scale` of the joints' velocity limits
(below the 0.95 at which `joint_limit_watch` fires by default) and its change to their
acceleration limits, so the reference never asks the arm for more than it may do: near a
singularity the tool then falls behind its line rather than a joint running away.

The reference starts where the arm is (or at the position command a switched-to task continues)
and feeds the joints: `q_des` as a position command (a UR's servoJ, CSP, Dynamixel), or `q_des`,
`dq_des`, `ddq_des` into `computed_torque` for a torque-controlled arm.
"""

from __future__ import annotations

import numpy as np

from orccadd.kinematics import (
    ToolKinematics,
    task_error,
)
from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.modules.cartesian import TWIST_UNIT
from orccadd.state import JointState

References = tuple[list[float], list[float], list[float], float]


@register("resolved_rate")
class ResolvedRate(KernelModule):
    """Closed-loop inverse kinematics of the tool (see the module's doc): desired pose and twist
    in, joint position, velocity and acceleration references out, and the singular-value margin
    `smallest_singular_value` of the reference's Jacobian (m or rad per rad)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n, m = ctx.dof, ctx.model
        self.add_input("position_des_m", (3,), "m")
        self.add_input("orientation_des", (4,), "1")
        self.add_input("twist_des", (6,), TWIST_UNIT)
        self.add_output("q_des", (n,), "rad")
        self.add_output("dq_des", (n,), "rad/s")
        self.add_output("ddq_des", (n,), "rad/s^2")
        self.add_output("smallest_singular_value", (), "1")
        self.gain = self.add_parameter(
            "gain", 50.0, bounds=(0.0, 0.5 / ctx.period_s), unit="1/s", tunable=True
        )
        self.threshold = self.add_parameter(
            "singular_value_threshold", 0.05, bounds=(1e-4, 1.0), unit="1", tunable=True
        )
        self.max_damping = self.add_parameter("max_damping", 0.05, bounds=(0.0, 1.0), unit="1", tunable=True)
        self.centering = self.add_parameter(
            "joint_centering_gain", 0.0, bounds=(0.0, 10.0), unit="1/s", tunable=True
        )
        self.velocity_scale = self.add_parameter(
            "velocity_scale", 0.8, bounds=(0.01, 1.0), unit="1", tunable=True
        )
        self._kin = ToolKinematics(m)
        self._dt = ctx.period_s
        self._q_ref = m.home_rad.copy()
        self._dq_prev = np.zeros(n)
        self._v = np.zeros(6)
        self._mid = 0.5 * (m.q_min_rad + m.q_max_rad)
        self._range2 = (m.q_max_rad - m.q_min_rad) ** 2
        self._vmax, self._amax = m.v_max_rad_s, m.a_max_rad_s2
        self._qmin, self._qmax = m.q_min_rad, m.q_max_rad
        self._eye = np.eye(n)

    def start(self, state: JointState) -> None:
        c = self.continued
        self._q_ref = (c.q_rad if c is not None else state.q_rad).copy()
        self._dq_prev = (c.dq_rad_s if c is not None else np.zeros(self.ctx.dof)).copy()

    def kernel(self) -> Kernel:
        kin, v, dt = self._kin, self._v, self._dt

        def resolved_rate(
            t_s: float, position_des_m: list[float], orientation_des: list[float], twist_des: list[float]
        ) -> References:
            q_ref = self._q_ref
            pose = kin.pose_and_jacobian(q_ref)
            j = kin.jacobian
            e = np.array(task_error(pose, position_des_m, orientation_des))
            v[:] = twist_des
            v[:] += float(self.gain.value) * e
            u, sv, vt = np.linalg.svd(j, full_matrices=False)  # one SVD: the margin and the inverse
            sigma = float(sv[-1])
            eps, lam_max = float(self.threshold.value), float(self.max_damping.value)
            damping2 = lam_max * lam_max * (1.0 - (sigma / eps) ** 2) if sigma < eps else 0.0
            gains = sv / (sv * sv + damping2)  # J⁺ = V·diag(σ/(σ² + λ²))·Uᵀ
            dq = vt.T @ (gains * (u.T @ v))
            k0 = float(self.centering.value)
            if k0 > 0.0:  # (I − J⁺J)·g, J⁺J = V·diag(σ²/(σ² + λ²))·Vᵀ
                g = -k0 * (q_ref - self._mid) / self._range2
                dq += g - vt.T @ ((sv * gains) * (vt @ g))
            dq = self._within_limits(dq)
            ddq = (dq - self._dq_prev) / dt
            self._dq_prev = dq
            self._q_ref = q_ref = np.minimum(np.maximum(q_ref + dq * dt, self._qmin), self._qmax)
            return (q_ref.tolist(), dq.tolist(), ddq.tolist(), sigma)

        return resolved_rate

    def _within_limits(self, dq: np.ndarray) -> np.ndarray:
        """`dq` scaled down to the velocity limits, its change from the last one to the
        acceleration limits (each in its direction)."""
        over = float(np.max(np.abs(dq) / self._vmax)) / float(self.velocity_scale.value)
        if over > 1.0:
            dq = dq / over
        step = dq - self._dq_prev
        over = float(np.max(np.abs(step) / (self._amax * self._dt)))
        if over > 1.0:
            dq = self._dq_prev + step / over
        return dq
