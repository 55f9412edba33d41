"""A switch between two position-mode tasks continues the outgoing task's last command and
blends the gap out no faster than the joints may move: a held grip (a gripper pressing on a
part, its command beyond where its fingers are) is released without a clamped, jumping command."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.session import Session
from orccadd.types import LIMIT_VIOLATION, CommandMode, Phase
from tests.conftest import ROOT, UR5E

HOLD = ROOT / "configs" / "tasks" / "hold_csp.toml"


def test_a_large_gap_is_blended_out_within_the_joints_speed() -> None:
    s = Session.open(UR5E, CommandMode.POSITION)
    try:
        res = s.resource
        period = res.config.control_period_s
        task = s.task(HOLD)
        res.read(0.0)
        q = res.state.q_rad.copy()
        previous = q.copy()
        previous[1] += 0.3  # the outgoing command 0.3 rad away from where the joint is
        for i in range(1, 61):  # the outgoing task commanded it, within the rate limit, in 60 ticks
            assert not res.write(0.0, q + (previous - q) * i / 60) & LIMIT_VIOLATION
        task.activate()
        task.continue_from(previous, blend_ticks=4)  # the daemon's default: 4 ticks at 500 Hz
        sent = [previous.copy()]
        flags = 0
        for k in range(1, 200):
            t = k * period
            res.read(t)
            task.tick(t)
            flags |= task.last_write_flags
            sent.append(res.last_command.copy())
        steps = np.abs(np.diff(np.array(sent), axis=0)).max(axis=0)
        assert not flags & LIMIT_VIOLATION
        assert (steps <= res.model.v_max_rad_s * period).all(), steps
        assert abs(sent[-1][1] - q[1]) < 0.01  # the gap blended out: holding where the joint is
    finally:
        s.close()


def test_a_torque_task_waiting_for_its_preconditions_holds_a_moving_arm() -> None:
    """After a switch, a torque task whose preconditions do not hold yet (move_joints' ArmSlow:
    the arm still moving) holds the arm in torque where it is, rather than the outgoing law's last
    torque: a stale feed-forward on a moving arm, with none of its watchers running yet. The arm
    comes to rest near where the wait began, and the law starts."""
    s = Session.open(UR5E, CommandMode.TORQUE)
    try:
        res = s.resource
        period = res.config.control_period_s
        data = res.model.new_data()
        t = 0.0
        push = np.zeros(res.dof)
        push[0] = 20.0  # the outgoing law's last torque: gravity + 20 N·m on the base joint
        for _ in range(150):  # spin the base joint up
            t += period
            st = res.read(t)
            previous = pin.computeGeneralizedGravity(res.model.model, data, st.q_rad) + push
            res.write(t, previous)
        assert abs(res.state.dq_rad_s[0]) > 0.5
        q_wait = res.state.q_rad.copy()
        task = s.task(ROOT / "configs" / "tasks" / "move_joints.toml")
        task.activate()
        task.continue_from(previous, blend_ticks=4)
        for _ in range(round(1.0 / period)):
            t += period
            res.read(t)
            task.tick(t)
            if task.phase is Phase.RUN:
                break
        assert task.phase is Phase.RUN, (task.phase, res.state.dq_rad_s)  # ArmSlow met: at rest
        assert np.abs(res.state.q_rad - q_wait).max() < 0.2  # stopped near where the wait began
    finally:
        s.close()
