"""The Hold task's setpoint source: where the arm comes to rest, reached within the joints' limits."""

from __future__ import annotations

from ruckig import InputParameter, OutputParameter, Result, Ruckig

from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.modules.trajectory import ruckig_step
from orccadd.state import JointState
from orccadd.vec import clamped

Setpoints = tuple[list[float], list[float], list[float]]  # q_des, dq_des, ddq_des


@register("hold_position")
class HoldPosition(KernelModule):
    """Setpoint source of a hold: the measured position when the task starts, zero velocity.

    On an arm at rest that is all. Started on a moving arm (a switch to Hold mid-motion), it does
    not jump its setpoint to that position: it takes the setpoint there along a jerk-limited,
    time-optimal path (Ruckig) within `limit_scale` of the robot's velocity, acceleration and
    jerk limits, continuous in position, velocity and acceleration with what it starts from:

    - a position task continuing a position command (`Module.continued`: servoJ, CSP) starts
      from that command, its velocity and acceleration, since the device follows the command and
      not the measured state (the command leads the arm by the servo's tracking lag);
    - otherwise (a torque hold, a fresh start after a reset) from the measured position and
      velocity.

    The arm so brakes, overshoots the held position by its stopping distance and comes back to
    it (at 0.3 rad/s and half a UR's limits: about 0.03 rad). The position is where the arm was,
    not where a stop would end: after a guarded move's contact, the hold is where it touched,
    not pressed further in by the stopping distance.
    """

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n, m = ctx.dof, ctx.model
        self.q_des = self.add_output("q_des", (n,), "rad")
        self.dq_des = self.add_output("dq_des", (n,), "rad/s")
        self.ddq_des = self.add_output("ddq_des", (n,), "rad/s^2")
        self.limit_scale = self.add_parameter("limit_scale", 0.5, bounds=(0.01, 1.0), unit="1")
        self._zeros = [0.0] * n
        self._outs: Setpoints = (m.home_rad.tolist(), self._zeros, self._zeros)
        self._hold: list[float] = self._outs[0]  # where the setpoint comes to rest
        self._otg = Ruckig(n, ctx.period_s)
        self._inp = InputParameter(n)
        self._out = OutputParameter(n)
        self._settled = True
        self.last_result = Result.Finished
        self.on_parameter_change("limit_scale")

    def on_parameter_change(self, name: str) -> None:
        m, s = self.ctx.model, float(self.limit_scale.value)
        self._inp.max_velocity = (m.v_max_rad_s * s).tolist()
        self._inp.max_acceleration = (m.a_max_rad_s2 * s).tolist()
        self._inp.max_jerk = (m.j_max_rad_s3 * s).tolist()

    def start(self, state: JointState) -> None:
        q_m, v_m = state.q_rad.tolist(), state.dq_rad_s.tolist()
        hold = q_m
        c = self.continued
        if c is not None:  # a command beyond the joints' limits is not continued beyond them
            m = self.ctx.model
            q0 = c.q_rad.tolist()
            v0 = clamped(c.dq_rad_s.tolist(), (-m.v_max_rad_s).tolist(), m.v_max_rad_s.tolist())
            a0 = clamped(c.ddq_rad_s2.tolist(), (-m.a_max_rad_s2).tolist(), m.a_max_rad_s2.tolist())
        else:
            q0, v0, a0 = q_m, v_m, self._zeros
        if q0 == hold and not any(v0) and not any(a0):  # at rest where it is: nothing to plan
            self._settled = True
            self._outs = (hold, self._zeros, self._zeros)
        else:
            inp = self._inp
            inp.current_position, inp.current_velocity, inp.current_acceleration = q0, v0, a0
            inp.target_position = hold
            inp.target_velocity = self._zeros
            inp.target_acceleration = self._zeros
            self._settled = False
            self._outs = (q0, v0, a0)
        self._hold = hold
        self.q_des.value[:] = self._outs[0]
        self.dq_des.value[:] = self._outs[1]
        self.ddq_des.value[:] = self._outs[2]

    def kernel(self) -> Kernel:
        otg, inp, out = self._otg, self._inp, self._out
        working, finished = Result.Working, Result.Finished

        def hold(t_s: float) -> Setpoints:
            if self._settled:
                return self._outs
            result = ruckig_step(otg, inp, out)
            self.last_result = result
            if result == finished:
                self._settled = True
                self._outs = (self._hold, self._zeros, self._zeros)
            elif result == working:
                self._outs = (out.new_position, out.new_velocity, out.new_acceleration)
                out.pass_to_input(inp)
            else:  # invalid input or calculation error: stay at the last setpoint
                self._settled = True
                self._outs = (self._outs[0], self._zeros, self._zeros)
            return self._outs

        return hold
