"""Ruckig online trajectory generation in joint space (jerk-limited, time-optimal)."""

from __future__ import annotations

import numpy as np
from ruckig import InputParameter, OutputParameter, Result, Ruckig

from orccadd.modules.base import Module, ModuleContext, register
from orccadd.state import JointState


@register("ruckig_trajectory")
class RuckigTrajectory(Module):
    """Jerk-limited trajectory to `target_rad`, within the robot's limits times `speed_scale`.

    Starts from the *measured* position and velocity. A new `target_rad` (or `speed_scale`)
    mid-motion is followed from the current trajectory state, so acceleration stays continuous
    and the commanded torque does not jump. Outputs the desired position, velocity and
    acceleration, the goal (`q_goal`) and `finished` once the trajectory has ended.
    """

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        n, m = ctx.dof, ctx.model
        self.q = self.add_input("q", (n,), "rad")
        self.dq = self.add_input("dq", (n,), "rad/s")
        self.q_des = self.add_output("q_des", (n,), "rad")
        self.dq_des = self.add_output("dq_des", (n,), "rad/s")
        self.ddq_des = self.add_output("ddq_des", (n,), "rad/s^2")
        self.q_goal = self.add_output("q_goal", (n,), "rad")
        self.finished = self.add_output("finished", (), "bool", dtype=np.bool_)
        self.target = self.add_parameter(
            "target_rad",
            m.home_rad,
            bounds=(m.q_min_rad, m.q_max_rad),
            unit="rad",
            tunable=True,
            shape=(n,),
            required=True,  # a goal: a copied task without one would go home
        )
        self.speed_scale = self.add_parameter("speed_scale", 1.0, bounds=(0.01, 1.0), unit="1", tunable=True)
        self._otg = Ruckig(n, ctx.period_s)
        self._inp = InputParameter(n)
        self._out = OutputParameter(n)
        self.last_result = Result.Working
        self._settled = False  # at the target, exactly: nothing left to compute
        self._apply_limits()
        self.q_goal.value[:] = self.target.value

    def _apply_limits(self) -> None:
        m, s = self.ctx.model, float(self.speed_scale.value)
        self._inp.max_velocity = (m.v_max_rad_s * s).tolist()
        self._inp.max_acceleration = (m.a_max_rad_s2 * s).tolist()
        self._inp.max_jerk = (m.j_max_rad_s3 * s).tolist()

    def start(self, state: JointState) -> None:
        inp = self._inp
        inp.current_position = state.q_rad.tolist()
        inp.current_velocity = state.dq_rad_s.tolist()
        inp.current_acceleration = [0.0] * self.ctx.dof
        inp.target_position = self.target.value.tolist()
        inp.target_velocity = [0.0] * self.ctx.dof
        inp.target_acceleration = [0.0] * self.ctx.dof
        self.q_des.value[:] = state.q_rad
        self.dq_des.value[:] = state.dq_rad_s
        self.ddq_des.value[:] = 0.0
        self.q_goal.value[:] = self.target.value
        self.finished.value[...] = False
        self._settled = False

    def on_parameter_change(self, name: str) -> None:
        if name == "speed_scale":
            self._apply_limits()
        else:
            self._settled = False
            self._inp.target_position = self.target.value.tolist()
            self.q_goal.value[:] = self.target.value
            self.finished.value[...] = False

    def update(self, t_s: float) -> None:
        if self._settled:  # holds the target; Ruckig is not asked again until it changes
            return
        result = self._otg.update(self._inp, self._out)
        self.last_result = result
        if result == Result.Working or result == Result.Finished:
            out = self._out
            self.q_des.value[:] = out.new_position
            self.dq_des.value[:] = out.new_velocity
            self.ddq_des.value[:] = out.new_acceleration
            out.pass_to_input(self._inp)
            self.finished.value[...] = result == Result.Finished
            if result == Result.Finished:
                self._settle()
        else:  # invalid input or calculation error: hold the last desired position
            self.dq_des.value[:] = 0.0
            self.ddq_des.value[:] = 0.0

    def _settle(self) -> None:
        """Finished: the state becomes the target exactly. Ruckig's last step leaves velocities and
        accelerations of 1e-16, and from such a state a new limit (a `speed_scale` tune) made it
        fail ("error in step 2"): measured by the soak benchmark."""
        inp, n = self._inp, self.ctx.dof
        inp.current_position = self.target.value.tolist()
        inp.current_velocity = [0.0] * n
        inp.current_acceleration = [0.0] * n
        self.q_des.value[:] = self.target.value
        self.dq_des.value[:] = 0.0
        self.ddq_des.value[:] = 0.0
        self._settled = True
