"""Operational-space computed torque on the simulated UR5e (6 joints) and Panda (7: a null space
the posture holds), in simulated time: straight lines of the tool within a millimetre, each
ending at its goal."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.kinematics import ToolKinematics
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.types import Phase
from tests.conftest import PANDA, ROOT, UR5E

TASKS = ROOT / "configs" / "tasks"
HOMES = {
    "ur5e": (UR5E, [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]),
    "panda": (PANDA, [0.0, -0.7854, 0.0, -2.3562, 0.0, 1.5708, 0.7854]),
}


def module(task: RobotTask, name: str):  # type: ignore[no-untyped-def]
    return next(m for m in task.modules if m.name == name)


@pytest.mark.parametrize("robot", list(HOMES))
def test_the_tool_follows_straight_lines_within_a_millimetre(robot: str) -> None:
    config, home = HOMES[robot]
    s = Session.open(config)
    try:
        loop = s.loop(SimClock())
        go_home = s.task(TASKS / "move_joints.toml")
        module(go_home, "traj").configure({"target_rad": home})
        assert loop.run_task(go_home, timeout_s=10.0) is Phase.DONE
        kin = ToolKinematics(s.resource.model)
        path: list[np.ndarray] = []
        for offset in ([0.0, -0.3, 0.0], [0.2, 0.0, -0.2]):
            task = s.task(TASKS / "move_line_os.toml")
            line = module(task, "line")
            line.configure({"offset_m": offset})

            def step(t_s: float, task: RobotTask = task) -> None:
                task.tick(t_s)
                path.append(kin.pose(s.resource.state.q_rad).translation.copy())

            loop.executor.step = step
            path.clear()
            assert loop.run_task(task, timeout_s=10.0) is Phase.DONE, s.event_names()
            start, goal = path[0], np.asarray(line.outputs["position_goal_m"].value)
            u = (goal - start) / np.linalg.norm(goal - start)
            d = np.array(path) - start
            off_line = np.linalg.norm(d - np.outer(d @ u, u), axis=1)
            assert off_line.max() < 1e-3, (robot, offset, off_line.max())
            assert np.linalg.norm(path[-1] - goal) < 1e-3
    finally:
        s.close()
