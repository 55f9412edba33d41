"""Force in task space: hybrid position/force control, admittance, and the wrench from torques.

Wrenches follow the UR's `actual_TCP_force` and the simulated F/T sensor (orccadd/physres/
contact.py): the force and torque the world exerts on the tool, at the tool's point, on the
base axes (N, N·m): pressing the tool down on a table reads +Fz. The laws here shape the
*desired pose* fed to `resolved_rate` (orccadd/modules/kinematic_control.py), so the same task
runs on position-, velocity- and torque-controlled arms: the force loop is an admittance, as a
UR's force mode is.

- `hybrid_force`: on the task frame's axes selected by `force_axes`, the desired pose follows the
  force error (v = −gain·(w_setpoint − w)), elsewhere the incoming trajectory: Raibert and
  Craig's selection, with the force loop an integral (damping) one.
- `admittance`: about the incoming trajectory, a virtual mass-spring-damper driven by the
  measured wrench minus a setpoint, per axis of the task frame: compliance for a
  position-controlled arm.
- `wrench_from_torques`: the wrench estimated from the joint torques through Jᵀ, for a resource
  without a force sensor (quasi-static: the arm's acceleration is neglected).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.kinematics import ToolKinematics, clip_norm, quaternion_of, rotation_of
from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.modules.cartesian import TWIST_UNIT
from orccadd.state import JointState

WRENCH_UNIT = "N|N.m"
Pose = tuple[list[float], list[float], list[float]]  # position, orientation, twist


class _TaskFrameLaw(KernelModule):
    """Base of the laws that shape a desired pose: the desired pose and twist in and out, the
    measured wrench in, the task frame (`in_tool_axes`: the tool's axes when the task starts,
    else the base's) fixed for the task's life. `wrench_setpoint` is on the task frame's axes:
    the wrench the world should exert on the tool (to press along the tool's z on a surface,
    the surface pushes back along −z: a setpoint of −F on the tool's z)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        tool = ctx.model.tool
        self.add_input("position_des_m", (3,), "m")
        self.add_input("orientation_des", (4,), "1")
        self.add_input("twist_des", (6,), TWIST_UNIT)
        self.add_input("wrench", (6,), WRENCH_UNIT)
        self.add_output("position_ref_m", (3,), "m")
        self.add_output("orientation_ref", (4,), "1")
        self.add_output("twist_ref", (6,), TWIST_UNIT)
        limit = [tool.max_force_n] * 3 + [tool.max_torque_nm] * 3
        self.setpoint = self.add_parameter(
            "wrench_setpoint",
            [0.0] * 6,
            bounds=(np.negative(limit), np.array(limit)),
            unit=WRENCH_UNIT,
            tunable=True,
            shape=(6,),
            per_joint=True,
            element="axis",
        )
        self.tool_axes = self.add_parameter("in_tool_axes", 0, bounds=(0, 1), unit="1", integer=True)
        self._kin = ToolKinematics(ctx.model)
        self._dt = ctx.period_s
        self._r_task = np.eye(3)  # the task frame's axes, on the base's
        self._p0 = np.zeros(3)
        self._r0 = np.eye(3)

    def start(self, state: JointState) -> None:
        pose = self._kin.pose(state.q_rad)
        self._p0, self._r0 = pose.translation.copy(), pose.rotation.copy()
        self._r_task = self._r0.copy() if int(self.tool_axes.value) else np.eye(3)

    def _in_task(self, v6: list[float]) -> np.ndarray:
        """A six-vector of base axes on the task frame's."""
        r = self._r_task
        return np.concatenate((r.T @ np.asarray(v6[:3]), r.T @ np.asarray(v6[3:])))

    def _in_base(self, v6: np.ndarray) -> np.ndarray:
        r = self._r_task
        return np.concatenate((r @ v6[:3], r @ v6[3:]))


@register("hybrid_force")
class HybridForce(_TaskFrameLaw):
    """Hybrid position/force control (see the module's doc). On each axis of the task frame with
    `force_axes` 1 the desired pose moves at −`gain`·(setpoint − measured) (m/s per N on the
    linear axes, rad/s per N·m on the angular ones), at most `max_speed_m_s` / `max_speed_rad_s`,
    from where the tool was when the task started; on the others it is the incoming trajectory's.
    Outputs the reference pose and twist for `resolved_rate`, and the force error (setpoint −
    measured, task frame) on the selected axes (zero on the others)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_output("wrench_error", (6,), WRENCH_UNIT)
        self.axes = self.add_parameter(
            "force_axes",
            [0, 0, 1, 0, 0, 0],
            bounds=(0, 1),
            unit="1",
            shape=(6,),
            integer=True,
            per_joint=True,
            element="axis",
        )
        self.gain = self.add_parameter("gain_m_s_n", 0.002, bounds=(0.0, 0.1), unit="m/(s.N)", tunable=True)
        self.rgain = self.add_parameter(
            "gain_rad_s_nm", 0.02, bounds=(0.0, 1.0), unit="rad/(s.N.m)", tunable=True
        )
        self.vmax = self.add_parameter("max_speed_m_s", 0.05, bounds=(0.0, 1.0), unit="m/s", tunable=True)
        self.wmax = self.add_parameter("max_speed_rad_s", 0.2, bounds=(0.0, 3.0), unit="rad/s", tunable=True)
        self._offset = np.zeros(6)  # the force loop's displacement from the start, task frame

    def start(self, state: JointState) -> None:
        super().start(state)
        self._offset = np.zeros(6)

    def kernel(self) -> Kernel:
        dt = self._dt

        def hybrid(
            t_s: float, p_des: list[float], o_des: list[float], twist_des: list[float], wrench: list[float]
        ) -> tuple[list[float], list[float], list[float], list[float]]:
            sel = self.axes.value > 0.5
            err = np.where(sel, self.setpoint.value - self._in_task(wrench), 0.0)
            v = -np.concatenate((float(self.gain.value) * err[:3], float(self.rgain.value) * err[3:]))
            v[:3] = clip_norm(v[:3], float(self.vmax.value))
            v[3:] = clip_norm(v[3:], float(self.wmax.value))
            self._offset += v * dt
            # the trajectory's pose and twist on the task frame, its selected axes replaced
            r0, rt = self._r0, self._r_task
            along = rt.T @ (np.asarray(p_des) - self._p0)
            turned = rt.T @ pin.log3(rotation_of(o_des) @ r0.T)
            along[sel[:3]] = self._offset[:3][sel[:3]]
            turned[sel[3:]] = self._offset[3:][sel[3:]]
            twist = self._in_task(twist_des)
            twist[sel] = v[sel]
            position = (self._p0 + rt @ along).tolist()
            orientation = quaternion_of(pin.exp3(rt @ turned) @ r0)
            return (position, orientation, self._in_base(twist).tolist(), err.tolist())

        return hybrid


@register("admittance")
class Admittance(_TaskFrameLaw):
    """Compliance about the incoming trajectory: per axis of the task frame, a displacement x
    with M·ẍ + D·ẋ + K·x = w − setpoint (`mass_kg`, `damping_n_s_m`, `stiffness_n_m` on the
    linear axes; the angular ones use `rotational_ratio` times them, in kg·m², N·m·s/rad,
    N·m/rad), added to the desired pose: the tool gives way to a push and comes back (K > 0) or
    stays where it was pushed (K = 0). Integrated semi-implicitly each tick; the displacement's
    speed at most `max_speed_m_s`."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_output("displacement", (6,), "m|rad")
        self.mass = self.add_parameter("mass_kg", 2.0, bounds=(0.01, 1000.0), unit="kg", tunable=True)
        self.damping = self.add_parameter(
            "damping_n_s_m", 200.0, bounds=(0.0, 1e5), unit="N.s/m", tunable=True
        )
        self.stiffness = self.add_parameter(
            "stiffness_n_m", 500.0, bounds=(0.0, 1e6), unit="N/m", tunable=True
        )
        self.ratio = self.add_parameter(
            "rotational_ratio", 0.05, bounds=(1e-4, 10.0), unit="m^2", tunable=True
        )
        self.vmax = self.add_parameter("max_speed_m_s", 0.1, bounds=(0.0, 1.0), unit="m/s", tunable=True)
        self._x = np.zeros(6)
        self._v = np.zeros(6)

    def start(self, state: JointState) -> None:
        super().start(state)
        self._x, self._v = np.zeros(6), np.zeros(6)

    def kernel(self) -> Kernel:
        dt = self._dt

        def admit(
            t_s: float, p_des: list[float], o_des: list[float], twist_des: list[float], wrench: list[float]
        ) -> tuple[list[float], list[float], list[float], list[float]]:
            scale = np.array([1.0, 1.0, 1.0] + [float(self.ratio.value)] * 3)
            m, d, k = (float(p.value) * scale for p in (self.mass, self.damping, self.stiffness))
            force = self._in_task(wrench) - self.setpoint.value
            # semi-implicit Euler: the new velocity first, from the spring at the old position
            self._v = (self._v + dt * (force - k * self._x) / m) / (1.0 + dt * d / m)
            self._v[:3] = clip_norm(self._v[:3], float(self.vmax.value))
            self._x = self._x + dt * self._v
            x_base = self._in_base(self._x)
            position = (np.asarray(p_des) + x_base[:3]).tolist()
            orientation = quaternion_of(pin.exp3(x_base[3:]) @ rotation_of(o_des))
            twist = (np.asarray(twist_des) + self._in_base(self._v)).tolist()
            return (position, orientation, twist, self._x.tolist())

        return admit


@register("wrench_from_torques")
class WrenchFromTorques(KernelModule):
    """The wrench on the tool estimated from the measured joint torques, for a resource without
    a force sensor: W = (Jᵀ)⁺·(g(q) + C(q, dq)·dq − τ) (the arm's dynamics at rest, the motor
    torques τ the resource measures or estimates: its `describe` says which), minus the reading
    at the task's start if `zero_at_start` (a bias: payload, model errors). Quasi-static: while the
    arm accelerates the estimate carries M(q)·ddq too. Its accuracy is the model's and the
    torques': a UR's or a sensor's wrench is better where there is one."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.add_input("q", (n,), "rad")
        self.add_input("dq", (n,), "rad/s")
        self.add_input("tau", (n,), "N.m")
        self.add_output("wrench", (6,), WRENCH_UNIT)
        self.zero = self.add_parameter("zero_at_start", 1, bounds=(0, 1), unit="1", integer=True)
        self._kin = ToolKinematics(ctx.model)
        self._model, self._data = ctx.model.model, ctx.model.new_data()
        self._q, self._dq, self._zero_acc = np.zeros(n), np.zeros(n), np.zeros(n)
        self._bias: np.ndarray | None = None

    def start(self, state: JointState) -> None:
        self._bias = None  # taken at the first tick

    def kernel(self) -> Kernel:
        kin, model, data = self._kin, self._model, self._data
        qa, dqa, zero_acc = self._q, self._dq, self._zero_acc

        def estimate(t_s: float, q: list[float], dq: list[float], tau: list[float]) -> tuple[list[float]]:
            qa[:], dqa[:] = q, dq
            kin.pose_and_jacobian(qa)
            external = pin.rnea(model, data, qa, dqa, zero_acc) - np.asarray(tau)
            w = np.linalg.lstsq(kin.jacobian.T, external, rcond=1e-6)[0]
            if int(self.zero.value):
                if self._bias is None:
                    self._bias = w.copy()
                w = w - self._bias
            return (w.tolist(),)

        return estimate
