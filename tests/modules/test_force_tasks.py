"""The shipped force task (configs/tasks/press.toml, press_csp.toml) on the simulated arm with a
table in its world, in simulated time: it presses with its setpoint and holds the tool's other
axes; with nothing under the tool it is a type 2 NoContact; pressing too hard is a type 3."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from orccadd.kinematics import ToolKinematics
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.task.loop import ControlLoop
from orccadd.types import CommandMode, Phase
from tests.conftest import ROOT, UR5E

TASKS = ROOT / "configs" / "tasks"
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]  # the tool at z = 0.4879 m, pointing down
TABLE = "world_planes = [{ point_m = [0.0, 0.0, 0.45], normal = [0.0, 0.0, 1.0], stiffness_n_m = 5000.0 }]\n"
MODES = {
    "torque": (CommandMode.TORQUE, "move_joints.toml", "press.toml"),
    "position": (CommandMode.POSITION, "move_joints_csp.toml", "press_csp.toml"),
}


def module(task: RobotTask, name: str):  # type: ignore[no-untyped-def]
    return next(m for m in task.modules if m.name == name)


@contextmanager
def arm_at_home(tmp: Path, mode: str, world: str) -> Iterator[tuple[Session, ControlLoop]]:
    config = tmp / "table.toml"
    text = UR5E.read_text().replace('"../', f'"{UR5E.parent.parent}/')
    config.write_text(text.replace("seed = 1\n", "seed = 1\n" + world))
    s = Session.open(config, MODES[mode][0])
    try:
        loop = s.loop(SimClock())
        home = s.task(TASKS / MODES[mode][1])
        module(home, "traj").configure({"target_rad": HOME})
        assert loop.run_task(home, timeout_s=10.0) is Phase.DONE
        yield s, loop
    finally:
        s.close()


@pytest.mark.parametrize("mode", list(MODES))
def test_the_tool_presses_on_the_table_with_its_setpoint_and_holds_where_it_touched(
    mode: str, tmp_path: Path
) -> None:
    with arm_at_home(tmp_path, mode, TABLE) as (s, loop):
        kin = ToolKinematics(s.resource.model)
        start = kin.pose(s.resource.state.q_rad).translation.copy()
        press = s.task(TASKS / MODES[mode][2])
        assert loop.run_task(press, timeout_s=15.0) is Phase.DONE, s.event_names()
        fz = float(s.resource.signals["wrench"][2])  # the table's push on the tool, up
        assert abs(fz - 10.0) < 1.0, fz
        end = kin.pose(s.resource.state.q_rad).translation
        assert np.linalg.norm(end[:2] - start[:2]) < 1e-3  # x and y held
        assert abs(end[2] - (0.45 - fz / 5000.0)) < 1e-3  # in the table by the spring's give


def test_with_nothing_under_the_tool_it_is_a_type_2_no_contact(tmp_path: Path) -> None:
    with arm_at_home(tmp_path, "torque", "") as (s, loop):
        kin = ToolKinematics(s.resource.model)
        start = kin.pose(s.resource.state.q_rad).translation.copy()
        press = s.task(TASKS / "press.toml")
        assert loop.run_task(press, timeout_s=15.0) is Phase.ABORTED
        assert s.event_names()[-1] == "Press.T2.NoContact"
        travel = start[2] - kin.pose(s.resource.state.q_rad).translation[2]
        assert 0.049 < travel < 0.06  # down 5 cm (far.threshold_m), looking for it


def test_pressing_harder_than_the_task_allows_is_a_type_3(tmp_path: Path) -> None:
    with arm_at_home(tmp_path, "torque", TABLE) as (s, loop):
        press = s.task(TASKS / "press.toml")
        module(press, "hf").configure(
            {"wrench_setpoint": [0.0, 0.0, -60.0, 0.0, 0.0, 0.0]}
        )  # over.force_n 40
        assert loop.run_task(press, timeout_s=15.0) is Phase.FAULT
        assert s.event_names()[-1] == "Press.T3.Overforce"
