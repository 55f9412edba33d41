"""Task functions on the simulated arm, in simulated time: straight lines of the tool within a
millimetre, on the tool's axes, to an absolute pose turning it; the tool's speed limit; a goal
out of the workspace refused before anything moves; a singularity met with bounded joint speeds;
a held pose."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from orccadd.errors import ParameterError
from orccadd.kinematics import ToolKinematics, angle_between, rotation_of
from orccadd.modules import Module
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.task.loop import ControlLoop
from orccadd.types import CommandMode, Phase
from tests.conftest import ROOT, UR5E

TASKS = ROOT / "configs" / "tasks"
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
MODES = {  # the command mode, the shipped joint move and line task in it
    "torque": (CommandMode.TORQUE, "move_joints.toml", "move_line.toml"),
    "position": (CommandMode.POSITION, "move_joints_csp.toml", "move_line_csp.toml"),
}


class Arm:
    """A session on sim-ur5e in simulated time, the measured tool recorded every tick."""

    def __init__(self, s: Session, mode: str) -> None:
        self.s, self.mode = s, mode
        self.loop: ControlLoop = s.loop(SimClock())
        self.kin = ToolKinematics(s.resource.model)
        self.path: list[np.ndarray] = []
        self.q: list[np.ndarray] = []
        self.task: RobotTask | None = None
        self.loop.executor.step = self._step

    def _step(self, t_s: float) -> None:
        assert self.task is not None
        self.task.tick(t_s)
        self.path.append(self.kin.pose(self.s.resource.state.q_rad).translation.copy())
        self.q.append(self.s.resource.state.q_rad.copy())

    def run(self, task: RobotTask, timeout_s: float = 10.0) -> Phase:
        self.task = task
        self.path.clear()
        self.q.clear()
        return self.loop.run_task(task, timeout_s=timeout_s)

    def home(self) -> None:
        task = self.s.task(TASKS / MODES[self.mode][1])
        module(task, "traj").configure({"target_rad": HOME})
        assert self.run(task) is Phase.DONE, self.s.event_names()

    def line(self, tmp: Path | None = None, kind: str = "", **params: object) -> RobotTask:
        """The shipped line task of this mode, its line of type `kind` (a copy under `tmp`)."""
        file = TASKS / MODES[self.mode][2]
        if kind:
            assert tmp is not None
            text = file.read_text().replace('type = "line_by_offset"', f'type = "{kind}"')
            file = tmp / file.name
            file.write_text(text)
        task = self.s.task(file)
        module(task, "line").configure(params)
        return task


def module(task: RobotTask, name: str) -> Module:
    return next(m for m in task.modules if m.name == name)


@contextmanager
def open_arm(config: Path, mode: str) -> Iterator[Arm]:
    """A session on `config` in `mode`, the arm brought home."""
    s = Session.open(config, MODES[mode][0])
    try:
        a = Arm(s, mode)
        a.home()
        yield a
    finally:
        s.close()


@pytest.fixture(params=list(MODES))
def arm(request: pytest.FixtureRequest) -> Iterator[Arm]:
    with open_arm(UR5E, request.param) as a:
        yield a


def deviation_m(path: np.ndarray, start: np.ndarray, goal: np.ndarray) -> float:
    """The largest distance of the path's points from the segment start-goal."""
    u = (goal - start) / np.linalg.norm(goal - start)
    d = path - start
    along = np.clip(d @ u, 0.0, float(np.linalg.norm(goal - start)))
    return float(np.linalg.norm(d - np.outer(along, u), axis=1).max())


def test_the_tool_goes_out_and_back_along_straight_lines_within_a_millimetre(arm: Arm) -> None:
    for offset in ([0.0, -0.3, 0.0], [0.0, 0.3, 0.0], [0.2, 0.0, -0.2]):
        task = arm.line(offset_m=offset)
        line = module(task, "line")
        assert arm.run(task) is Phase.DONE, arm.s.event_names()
        start = arm.path[0]
        goal = np.array(line.outputs["position_goal_m"].value)
        assert np.allclose(goal - start, offset, atol=1e-3)
        path = np.array(arm.path)
        assert deviation_m(path, start, goal) < 1e-3, (offset, deviation_m(path, start, goal))
        assert np.linalg.norm(path[-1] - goal) < 1e-3  # pose_reached's tolerance
        end = arm.kin.pose(arm.s.resource.state.q_rad).rotation
        assert angle_between(rotation_of(line.outputs["orientation_goal"].value), end) < 0.01
    assert not any(".T" in e for e in arm.s.event_names()), arm.s.event_names()


def test_the_tool_moves_no_faster_than_its_limit_times_the_speed_scale(arm: Arm) -> None:
    task = arm.line(offset_m=[0.0, -0.3, 0.0], speed_scale=0.5)
    twists = []
    line = module(task, "line")
    step = arm.loop.executor.step

    def record(t_s: float) -> None:
        step(t_s)
        twists.append(np.linalg.norm(line.outputs["twist_des"].value[:3]))

    arm.loop.executor.step = record
    assert arm.run(task) is Phase.DONE
    limit = arm.s.resource.model.tool.max_linear_velocity_m_s * 0.5
    assert max(twists) <= limit + 1e-9 and max(twists) > 0.9 * limit  # reached, never passed
    speeds = np.linalg.norm(np.diff(np.array(arm.path), axis=0), axis=1) / arm.s.config.control_period_s
    assert speeds.max() < 1.1 * limit  # the arm follows it


def test_an_approach_along_the_tools_axis_goes_down_when_the_tool_points_down(
    arm: Arm, tmp_path: Path
) -> None:
    start = arm.kin.pose(arm.s.resource.state.q_rad)
    assert start.rotation[2, 2] < -0.99  # at home the tool's z points down
    assert arm.run(arm.line(tmp_path, "line_by_tool_offset", offset_m=[0.0, 0.0, 0.1])) is Phase.DONE
    end = arm.kin.pose(arm.s.resource.state.q_rad)
    assert np.allclose(end.translation - start.translation, [0.0, 0.0, -0.1], atol=1e-3)
    assert angle_between(start.rotation, end.rotation) < 0.01


def test_a_line_to_an_absolute_pose_turns_the_tool_on_the_way(arm: Arm, tmp_path: Path) -> None:
    target, rpy = [-0.45, -0.25, 0.45], [np.pi, 0.0, 0.5]  # pointing down, turned 0.5 rad about z
    assert (
        arm.run(arm.line(tmp_path, "line_to_pose", target_position_m=target, target_rpy_rad=rpy))
        is Phase.DONE
    )
    end = arm.kin.pose(arm.s.resource.state.q_rad)
    assert np.linalg.norm(end.translation - target) < 1e-3
    assert angle_between(end.rotation, rpy_matrix(rpy)) < 0.01
    assert deviation_m(np.array(arm.path), arm.path[0], np.array(target)) < 1e-3


def rpy_matrix(rpy: list[float]) -> np.ndarray:
    return np.asarray(pin.rpy.rpyToMatrix(*rpy))


@pytest.mark.parametrize("mode", list(MODES))
def test_a_goal_outside_the_workspace_is_a_type_2_before_anything_moves(mode: str, tmp_path: Path) -> None:
    box = "[workspace]\nbox_min_m = [-1.0, -0.4, 0.1]\nbox_max_m = [0.0, 0.4, 1.0]\n\n[safe_stop]"
    config = tmp_path / "boxed.toml"
    config.write_text(UR5E.read_text().replace('"../', f'"{UR5E.parent.parent}/').replace("[safe_stop]", box))
    with open_arm(config, mode) as arm:
        task = arm.line(offset_m=[0.0, -0.3, 0.0])  # from y = -0.13 to -0.43: out of the box
        q0 = arm.s.resource.state.q_rad.copy()
        assert arm.run(task) is Phase.ABORTED, arm.s.event_names()
        assert arm.s.event_names()[-1] == f"{task.name}.T2.OutsideWorkspace"
        assert np.abs(arm.s.resource.state.q_rad - q0).max() < 1e-3
        assert arm.run(arm.line(offset_m=[0.0, -0.2, 0.0])) is Phase.DONE  # within it: goes


def test_a_cartesian_vector_given_as_one_number_is_refused_naming_its_axes(arm: Arm) -> None:
    task = arm.s.task(TASKS / MODES[arm.mode][2])
    with pytest.raises(ParameterError, match=r"line.offset_m \(=0.3\) must be 3 numbers, one per axis"):
        module(task, "line").configure({"offset_m": 0.3})


def test_toward_the_wrist_singularity_the_task_ends_with_a_type_2_and_no_joint_runs_away(
    tmp_path: Path,
) -> None:
    with open_arm(UR5E, "torque") as arm:
        near = arm.s.task(TASKS / "move_joints.toml")
        module(near, "traj").configure({"target_rad": [0.0, -1.5708, 1.5708, -1.5708, -0.3, 0.0]})
        assert arm.run(near) is Phase.DONE
        # tilting the tool 0.35 rad about its y would take wrist 2 through 0 (wrists 1 and 3 aligned)
        task = arm.line(
            tmp_path, "line_by_tool_offset", offset_m=[0.0, 0.0, 0.0], rotation_rpy_rad=[0.0, -0.35, 0.0]
        )
        assert arm.run(task) is Phase.ABORTED
        assert arm.s.event_names()[-1] == "MoveLine.T2.NearSingularity"
        q = np.array(arm.q)
        assert -0.1 < q[-1, 4] < 0.0  # stopped short of it, where J's smallest singular value is 0.01
        speeds = np.abs(np.diff(q, axis=0)).max(axis=0) / arm.s.config.control_period_s
        assert (speeds < 0.8 * arm.s.resource.model.v_max_rad_s).all(), speeds


def test_a_held_pose_stays_put(arm: Arm) -> None:
    task = arm.s.task(TASKS / ("hold_pose.toml" if arm.mode == "torque" else "hold_pose_csp.toml"))
    start = arm.kin.pose(arm.s.resource.state.q_rad).copy()
    assert arm.run(task, timeout_s=1.0) is Phase.RUN  # no postcondition: it holds until switched
    drift = np.linalg.norm(np.array(arm.path) - start.translation, axis=1)
    assert drift.max() < 1e-4, drift.max()


def test_an_absolute_goal_outside_the_workspace_is_refused_when_it_is_set(tmp_path: Path) -> None:
    """As a mission's `set` line sets it at `load`: refused there, before anything runs."""
    box = "[workspace]\nbox_min_m = [-1.0, -0.5, 0.1]\nbox_max_m = [0.0, 0.5, 1.0]\n\n[safe_stop]"
    config = tmp_path / "boxed.toml"
    config.write_text(UR5E.read_text().replace('"../', f'"{UR5E.parent.parent}/').replace("[safe_stop]", box))
    s = Session.open(config)
    try:
        file = tmp_path / "to_pose.toml"
        file.write_text((TASKS / "move_line.toml").read_text().replace('"line_by_offset"', '"line_to_pose"'))
        line = module(s.task(file), "line")
        line.configure({"target_position_m": [-0.4, 0.0, 0.5]})  # inside
        with pytest.raises(
            ParameterError, match=r"line.target_position_m \(=\[0.2, 0, 0.5\]\) is outside the workspace"
        ):
            line.configure({"target_position_m": [0.2, 0.0, 0.5]})
    finally:
        s.close()
