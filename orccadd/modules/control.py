"""Joint-space control laws: computed torque, PD with gravity compensation, gravity hold."""

from __future__ import annotations

from operator import add, mul, sub

import numpy as np
import pinocchio as pin

from orccadd.modules.base import Module, ModuleContext, register
from orccadd.state import JointState
from orccadd.vec import clamped


class JointController(Module):
    """Base of joint-space laws: measured q, dq and desired q_des, dq_des in; torque out."""

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
        self._e = np.zeros(n)


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

    def update(self, t_s: float) -> None:
        q, dq = self.q.value, self.dq.value
        e = list(map(sub, self.q_des.value.tolist(), q.tolist()))
        de = map(sub, self.dq_des.value.tolist(), dq.tolist())
        ddq_des = self.ddq_des.value.tolist()
        terms = zip(ddq_des, self._kp, e, self._kd, de)  # noqa: B905 (see orccadd.vec.clamped)
        a = [ddq + kp * e_i + kd * de_i for ddq, kp, e_i, kd, de_i in terms]
        if self._integral:
            hi, lo = self._sum_max_list, self._sum_min_list
            self._e_sum = e_sum = clamped(list(map(add, self._e_sum, e)), lo, hi)
            a = list(map(add, a, map(mul, self._ki_dt, e_sum)))
        self._a[:] = a
        self.tau.value[:] = pin.rnea(self._model, self._data, q, dq, self._a)


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

    def update(self, t_s: float) -> None:
        tau, e = self.tau.value, self._e
        tau[:] = pin.computeGeneralizedGravity(self._model, self._data, self.q.value)
        np.subtract(self.q_des.value, self.q.value, out=e)
        e *= self.kp.value
        tau += e
        np.subtract(self.dq_des.value, self.dq.value, out=e)
        e *= self.kd.value
        tau += e


@register("gravity_compensation")
class GravityCompensation(Module):
    """tau = g(q): the arm floats where it is, held by its own friction (a "hold" law)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q = self.add_input("q", (n,), "rad")
        self.tau = self.add_output("tau", (n,), "N.m")
        self._model = ctx.model.model
        self._data = ctx.model.new_data()

    def update(self, t_s: float) -> None:
        self.tau.value[:] = pin.computeGeneralizedGravity(self._model, self._data, self.q.value)


@register("hold_position")
class HoldPosition(Module):
    """Setpoint source: the measured position when the task starts, zero velocity."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n = ctx.dof
        self.q_des = self.add_output("q_des", (n,), "rad")
        self.dq_des = self.add_output("dq_des", (n,), "rad/s")
        self.ddq_des = self.add_output("ddq_des", (n,), "rad/s^2")

    def start(self, state: JointState) -> None:
        self.q_des.value[:] = state.q_rad
        self.dq_des.value[:] = 0.0
        self.ddq_des.value[:] = 0.0

    def update(self, t_s: float) -> None:
        pass
