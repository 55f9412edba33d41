"""Joint-space control laws: computed torque, PD with gravity compensation, gravity hold."""

from __future__ import annotations

from operator import add, mul, sub

import numpy as np
import pinocchio as pin

from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.state import JointState
from orccadd.vec import clamped


class JointController(KernelModule):
    """Base of joint-space laws: measured q, dq and desired q_des, dq_des in; torque out.
    Written as kernels (`Module.kernel`): the laws compute on lists of floats, Pinocchio on
    the arrays `_qa`, `_dqa` filled from them."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q = self.add_input("q", (n,), "rad")
        self.dq = self.add_input("dq", (n,), "rad/s")
        self.q_des = self.add_input("q_des", (n,), "rad")
        self.dq_des = self.add_input("dq_des", (n,), "rad/s")
        self.tau = self.add_output("tau", (n,), "N.m")
        self._model = ctx.model.model
        self._data = ctx.model.new_data()
        self._qa = np.zeros(n)
        self._dqa = np.zeros(n)


@register("computed_torque")
class ComputedTorque(JointController):
    """tau = M(q)·(ddq_des + kp·e + kd·de + ki·∫e) + h(q, dq), computed in one RNEA call.

    `kp` (1/s²) and `kd` (1/s) set the error dynamics e'' + kd·e' + kp·e = 0 per joint; the
    optional integral term `ki` (1/s³; the integral is clamped to ±`integral_limit_rad_s`)
    removes the steady error that unmodelled friction leaves. The integral starts at zero.
    """

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.ddq_des = self.add_input("ddq_des", (n,), "rad/s^2")
        self.kp = self.add_parameter("kp", 400.0, bounds=(0.0, 1e5), unit="1/s^2", tunable=True, shape=(n,))
        self.kd = self.add_parameter("kd", 40.0, bounds=(0.0, 1e3), unit="1/s", tunable=True, shape=(n,))
        self.ki = self.add_parameter("ki", 0.0, bounds=(0.0, 1e6), unit="1/s^3", tunable=True, shape=(n,))
        self.i_max = self.add_parameter(
            "integral_limit_rad_s", 0.05, bounds=(0.0, 10.0), unit="rad.s", tunable=True
        )
        self._a = np.zeros(n)
        self._e_sum = [0.0] * n  # Σe over the ticks: ∫e = Σe·dt
        self._dt = ctx.period_s
        # from the parameters (on_parameter_change), as lists: the tick computes on lists
        self._kp: list[float] = []
        self._kd: list[float] = []
        self._ki_dt: list[float] = []  # ki·dt
        self._sum_max_list: list[float] = []  # the clamp of Σe
        self._sum_min_list: list[float] = []
        self._integral = False
        self.on_parameter_change("ki")

    def on_parameter_change(self, name: str) -> None:
        self._kp, self._kd = self.kp.value.tolist(), self.kd.value.tolist()
        self._ki_dt = (self.ki.value * self._dt).tolist()
        sum_max = float(self.i_max.value) / self._dt
        self._sum_max_list, self._sum_min_list = [sum_max] * self.ctx.dof, [-sum_max] * self.ctx.dof
        self._integral = any(self._ki_dt)

    def start(self, state: JointState) -> None:
        self._e_sum = [0.0] * self.ctx.dof

    def kernel(self) -> Kernel:
        model, data, qa, dqa, acc = self._model, self._data, self._qa, self._dqa, self._a
        rnea = pin.rnea

        def computed_torque(
            t_s: float,
            q: list[float],
            dq: list[float],
            q_des: list[float],
            dq_des: list[float],
            ddq_des: list[float],
        ) -> tuple[list[float]]:
            e = list(map(sub, q_des, q))
            de = map(sub, dq_des, dq)
            terms = zip(ddq_des, self._kp, e, self._kd, de)  # noqa: B905 (see orccadd.vec.clamped)
            a = [ddq + kp * e_i + kd * de_i for ddq, kp, e_i, kd, de_i in terms]
            if self._integral:
                hi, lo = self._sum_max_list, self._sum_min_list
                self._e_sum = e_sum = clamped(list(map(add, self._e_sum, e)), lo, hi)
                a = list(map(add, a, map(mul, self._ki_dt, e_sum)))
            qa[:], dqa[:], acc[:] = q, dq, a
            return (rnea(model, data, qa, dqa, acc).tolist(),)

        return computed_torque


@register("joint_pd_gravity")
class JointPDGravity(JointController):
    """tau = kp·(q_des − q) + kd·(dq_des − dq) + g(q): joint PD with gravity compensation."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        # stiffness in N.m/rad fits one arm only: a mission's task says it (no default used)
        self.kp = self.add_parameter(
            "kp", 200.0, bounds=(0.0, 1e5), unit="N.m/rad", tunable=True, shape=(n,), required=True
        )
        self.kd = self.add_parameter(
            "kd", 20.0, bounds=(0.0, 1e4), unit="N.m.s/rad", tunable=True, shape=(n,), required=True
        )

    def kernel(self) -> Kernel:
        model, data, qa = self._model, self._data, self._qa
        kp, kd, gravity = self.kp.value, self.kd.value, pin.computeGeneralizedGravity

        def pd_gravity(
            t_s: float, q: list[float], dq: list[float], q_des: list[float], dq_des: list[float]
        ) -> tuple[list[float]]:
            qa[:] = q
            g = gravity(model, data, qa).tolist()
            terms = zip(g, kp.tolist(), q_des, q, kd.tolist(), dq_des, dq)  # noqa: B905
            return ([g_i + p * (qd - q_i) + d * (dqd - dq_i) for g_i, p, qd, q_i, d, dqd, dq_i in terms],)

        return pd_gravity


@register("torque_blend")
class TorqueBlend(KernelModule):
    """tau = tau_a + weight·(tau_b − tau_a): two laws' torques cross-faded by a tunable weight
    (0: law a alone, 1: law b alone), e.g. a stiff law handing over to a compliant one."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.tau_a = self.add_input("tau_a", (n,), "N.m")
        self.tau_b = self.add_input("tau_b", (n,), "N.m")
        self.tau = self.add_output("tau", (n,), "N.m")
        self.weight = self.add_parameter("weight", 0.0, bounds=(0.0, 1.0), unit="1", tunable=True)

    def kernel(self) -> Kernel:
        weight = self.weight.value

        def blend(t_s: float, tau_a: list[float], tau_b: list[float]) -> tuple[list[float]]:
            w = float(weight)
            return ([a + w * (b - a) for a, b in zip(tau_a, tau_b)],)  # noqa: B905 (dof by construction)

        return blend


@register("gravity_compensation")
class GravityCompensation(KernelModule):
    """tau = g(q): the arm floats where it is, held by its own friction (a "hold" law)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q = self.add_input("q", (n,), "rad")
        self.tau = self.add_output("tau", (n,), "N.m")
        self._model = ctx.model.model
        self._data = ctx.model.new_data()
        self._qa = np.zeros(n)

    def kernel(self) -> Kernel:
        model, data, qa, gravity = self._model, self._data, self._qa, pin.computeGeneralizedGravity

        def gravity_only(t_s: float, q: list[float]) -> tuple[list[float]]:
            qa[:] = q
            return (gravity(model, data, qa).tolist(),)

        return gravity_only


@register("measured_position")
class MeasuredPosition(KernelModule):
    """Setpoint source for a task whose motion the device runs itself (a UR's force mode or
    freedrive): the measured position, each tick. The joint command then says where the arm is,
    so a task switch blends from there, never back to where the behaviour began."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.q = self.add_input("q", (ctx.dof,), "rad")
        self.q_des = self.add_output("q_des", (ctx.dof,), "rad")

    def kernel(self) -> Kernel:
        def measured(t_s: float, q: list[float]) -> tuple[list[float]]:
            return (q,)

        return measured
