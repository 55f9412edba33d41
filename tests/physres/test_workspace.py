"""The tool's workspace ([workspace] of the robot config) guarded by every resource: measured out
of it beyond its tolerance is a type 3 on any task, joint-space ones too; a position command
that would take the tool out is not sent; the words name where the tool was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orccadd.kinematics import ToolKinematics, ToolWorkspace
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.types import CommandMode, Phase, Status
from tests.conftest import ROOT, UR5E

TASKS = ROOT / "configs" / "tasks"
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
# at HOME the tool is at (-0.49, -0.13, 0.49), at the sim's initial pose y = -0.32: a box whose +y side
# is 0.13 m from HOME
BOX = "[workspace]\nbox_min_m = [-1.0, -0.5, 0.1]\nbox_max_m = [0.0, 0.0, 1.0]\ntolerance_m = 0.005\n"
OUT_OF_BOX = [-0.4, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]  # the pan turns the tool to y = +0.069


def boxed(tmp: Path) -> Path:
    path = tmp / "boxed.toml"
    text = UR5E.read_text().replace('"../', f'"{UR5E.parent.parent}/')
    path.write_text(text.replace("[safe_stop]", BOX + "\n[safe_stop]"))
    return path


@pytest.mark.parametrize(
    ("mode", "task_file"),
    [(CommandMode.TORQUE, "move_joints.toml"), (CommandMode.POSITION, "move_joints_csp.toml")],
)
def test_a_joint_move_taking_the_tool_out_of_the_workspace_is_stopped_at_its_edge(
    mode: CommandMode, task_file: str, tmp_path: Path
) -> None:
    s = Session.open(boxed(tmp_path), mode)
    try:
        loop = s.loop(SimClock())
        kin = ToolKinematics(s.resource.model)
        home = s.task(TASKS / task_file)
        next(m for m in home.modules if m.name == "traj").configure({"target_rad": HOME})
        assert loop.run_task(home, timeout_s=10.0) is Phase.DONE
        out = s.task(TASKS / task_file)
        next(m for m in out.modules if m.name == "traj").configure({"target_rad": OUT_OF_BOX})
        ys: list[float] = []
        step = loop.executor.step

        def record(t_s: float) -> None:
            step(t_s)
            ys.append(float(kin.pose(s.resource.state.q_rad).translation[1]))  # the tool's y

        loop.executor.step = record
        assert loop.run_task(out, timeout_s=10.0) is Phase.FAULT, s.event_names()
        assert s.event_names()[-1] == f"{out.name}.T3.LimitViolation"
        message = s.resource.fault_message
        assert "outside the workspace (box [-1.0, -0.5, 0.1]..[0.0, 0.0, 1.0] m)" in message, message
        if mode is CommandMode.POSITION:  # the command that would leave is held, before the arm does
            assert "command not sent: tool at (" in message, message
            assert max(ys) < 0.0 + 1e-9
        else:  # measured beyond the tolerance: the arm's safe stop ends a little further out
            assert "measured tool at (" in message, message
            assert max(ys) > 0.005
            assert s.resource.state.status & Status.LIMIT_VIOLATION  # and still is
            loop.executor.run(max_ticks=2000, until=lambda: bool(s.resource.state.status & Status.STOPPED))
            s.resource.clear_stop()  # stopped outside: it may be brought back in, not further out
            back = s.task(TASKS / task_file)
            next(m for m in back.modules if m.name == "traj").configure({"target_rad": HOME})
            assert loop.run_task(back, timeout_s=10.0) is Phase.DONE, s.event_names()
            assert max(ys[-100:]) < 0.0
    finally:
        s.close()


def test_the_excess_is_the_distance_out_of_the_box_or_out_of_the_sphere(tmp_path: Path) -> None:
    config = boxed(tmp_path)
    sphere = "sphere_center_m = [0.0, 0.0, 0.0]\nsphere_radius_m = 0.65\n"
    config.write_text(config.read_text().replace("tolerance_m = 0.005\n", "tolerance_m = 0.005\n" + sphere))
    s = Session.open(config)
    try:
        ws = ToolWorkspace.of(s.resource.model)
        assert ws is not None
        home = np.array([-0.4919, -0.1333, 0.4879])  # in the box, 0.706 m from the base
        assert np.isclose(ws.excess_m(HOME), np.linalg.norm(home) - 0.65, atol=1e-3)
        assert np.isclose(ws.excess_m(OUT_OF_BOX), 0.0688, atol=1e-3)  # beyond the box's +y side
        assert ws.excess_m([np.nan] * 6) == np.inf
        assert (
            "outside the workspace (box [-1.0, -0.5, 0.1]..[0.0, 0.0, 1.0] m and sphere of 0.65 m"
            in ws.describe_outside()
        )
    finally:
        s.close()
    plain = Session.open(UR5E)
    try:
        assert ToolWorkspace.of(plain.resource.model) is None  # no [workspace]: no guard
    finally:
        plain.close()
