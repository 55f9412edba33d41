"""A switch between two position-mode tasks continues the outgoing task's last command and
blends the gap out no faster than the joints may move: a held grip (a gripper pressing on a
part, its command beyond where its fingers are) is released without a clamped, jumping command."""

from __future__ import annotations

import numpy as np

from orccadd.session import Session
from orccadd.types import LIMIT_VIOLATION, CommandMode
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
