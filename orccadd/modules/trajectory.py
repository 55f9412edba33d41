"""Ruckig online trajectory generation in joint space (jerk-limited, time-optimal)."""

from __future__ import annotations

import numpy as np
from ruckig import InputParameter, OutputParameter, Result, Ruckig, RuckigError

from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.state import JointState

Outputs = tuple[list[float], list[float], list[float], list[float], bool]  # the outputs, in order
NUDGE = 1.0 - 1e-9  # the jerk limits' relative nudge when Ruckig fails at a profile's boundary


def ruckig_step(otg: Ruckig, inp: InputParameter, out: OutputParameter) -> Result:
    """One Ruckig update, as robust as Ruckig 0.19.4 allows (tick-safe: no allocation on the usual
    path). It raises `RuckigError` ("error in step 1") for a motion exactly at the boundary between
    two profile shapes, e.g. 0.1 rad at 5 rad/s² and 50 rad/s³ (d = 2a³/j²): what `orccadctl jog
    --by 0.1` asked of a UR5e's wrist. The same motion with the jerk limits a billionth lower is off
    the boundary: retried once so; a second failure, or a code the binding's enum lacks (-101,
    duration too long: a `ValueError`), is `Result.Error` (the caller holds its last setpoint)."""
    try:
        return otg.update(inp, out)
    except ValueError:
        return Result.Error
    except RuckigError:
        inp.max_jerk = [j * NUDGE for j in inp.max_jerk]
    try:
        return otg.update(inp, out)
    except (ValueError, RuckigError):
        return Result.Error


@register("ruckig_trajectory")
class RuckigTrajectory(KernelModule):
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
            per_joint=True,
        )
        self.speed_scale = self.add_parameter("speed_scale", 1.0, bounds=(0.01, 1.0), unit="1", tunable=True)
        self._otg = Ruckig(n, ctx.period_s)
        self._inp = InputParameter(n)
        self._out = OutputParameter(n)
        self.last_result = Result.Working
        self._settled = False  # at the target, exactly: nothing left to compute
        self._apply_limits()
        self.q_goal.value[:] = self.target.value
        zeros = [0.0] * n
        self._zeros = zeros
        self._outs: Outputs = (zeros, zeros, zeros, self.target.value.tolist(), False)

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
        self._outs = (state.q_rad.tolist(), state.dq_rad_s.tolist(), self._zeros, inp.target_position, False)
        self._settled = False

    def on_parameter_change(self, name: str) -> None:
        if name == "speed_scale":
            self._apply_limits()
        else:
            self._settled = False
            goal = self.target.value.tolist()
            self._inp.target_position = goal
            q_des, dq_des, ddq_des = self._outs[:3]
            self._outs = (q_des, dq_des, ddq_des, goal, False)

    def kernel(self) -> Kernel:
        otg, inp, out = self._otg, self._inp, self._out
        working, finished = Result.Working, Result.Finished

        def trajectory(t_s: float, q: list[float], dq: list[float]) -> Outputs:
            if self._settled:  # holds the target; Ruckig is not asked again until it changes
                return self._outs
            result = ruckig_step(otg, inp, out)
            self.last_result = result
            goal = self._outs[3]
            if result in (working, finished):
                done = result == finished
                self._outs = (out.new_position, out.new_velocity, out.new_acceleration, goal, done)
                out.pass_to_input(inp)
                if done:
                    self._settle()
            else:  # invalid input or calculation error: hold the last desired position
                self._outs = (self._outs[0], self._zeros, self._zeros, goal, self._outs[4])
            return self._outs

        return trajectory

    def _settle(self) -> None:
        """Finished: the state becomes the target exactly. Ruckig's last step leaves velocities and
        accelerations of 1e-16, and from such a state a new limit (a `speed_scale` tune) made it
        fail ("error in step 2"): measured by the soak benchmark."""
        inp, n = self._inp, self.ctx.dof
        inp.current_position = self.target.value.tolist()
        inp.current_velocity = [0.0] * n
        inp.current_acceleration = [0.0] * n
        goal = self.target.value.tolist()
        self._outs = (goal, self._zeros, self._zeros, goal, True)
        self._settled = True


@register("ruckig_trajectory_scaled")
class ScaledRuckigTrajectory(RuckigTrajectory):
    """`ruckig_trajectory` on a time base that the resource's speed scaling slows, as a UR
    controller slows its own trajectories by its speed slider (wire `arm.speed_scaling`: the
    slider times the controller's own scaling). At a fraction s the trajectory advances s of a
    period each period, its velocity times s and its acceleration times s²; at 0 it holds where
    it is, and goes on from there when the scaling comes back."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.scaling = self.add_input("speed_scaling", (1,), "1")

    def kernel(self) -> Kernel:
        advance, otg, period_s = super().kernel(), self._otg, self.ctx.period_s

        def scaled_trajectory(
            t_s: float, q: list[float], dq: list[float], speed_scaling: list[float]
        ) -> Outputs:
            s = min(max(float(speed_scaling[0]), 0.0), 1.0)
            if s <= 0.0:  # held: the last desired position, at rest
                q_des, _, _, goal, done = self._outs
                return (q_des, self._zeros, self._zeros, goal, done)
            otg.delta_time = period_s * s
            q_des, dq_des, ddq_des, goal, done = advance(t_s, q, dq)
            if s == 1.0:
                return (q_des, dq_des, ddq_des, goal, done)
            s2 = s * s
            return (q_des, [v * s for v in dq_des], [a * s2 for a in ddq_des], goal, done)

        return scaled_trajectory
