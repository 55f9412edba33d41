"""What `move`, `jog` and `follow` check before the daemon loads anything (no daemon here): the
target's count and ranges, a trajectory CSV's form, its motion and its start; the mission they
write passes the checks of `orccadctl check` against the robot."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from orccadd.config.station import StationConfig
from orccadd.daemon.adhoc import (
    check_target,
    check_trajectory,
    mission_text,
    mode_for,
    move_pose,
    parse_csv,
    task_file,
)
from orccadd.daemon.replies import CommandError
from orccadd.mission import check_mission, check_on_robot
from orccadd.modules.follow import JointTrajectory
from orccadd.robot import create_resource, load_robot_config
from orccadd.types import CommandMode
from tests.conftest import ROOT, UR5E

CFG = load_robot_config(UR5E)
NAMES = CFG.joint_names
HOME = [j.home_rad for j in CFG.joints]
HEADER = "t_s," + ",".join(NAMES)


def csv(*rows: list[float], header: str = HEADER) -> str:
    return "\n".join([header, *(",".join(map(str, r)) for r in rows)]) + "\n"


def test_a_target_of_the_wrong_count_or_out_of_range_is_refused_naming_the_joint() -> None:
    check_target(CFG, HOME, "move")
    with pytest.raises(CommandError, match=r"^move: 5 values for the 6 joints of arm \(shoulder_pan_joint, "):
        check_target(CFG, HOME[:5], "move")
    with pytest.raises(
        CommandError,
        match=r"move: wrist_3_joint \(joint 5\) = 7 rad is outside its range \[-6.2831, 6.2831\] rad "
        r"\(joints\[5\].position_min_rad/max_rad in .*sim-ur5e.toml\)",
    ):
        check_target(CFG, [*HOME[:5], 7.0], "move")


def test_a_csv_is_read_in_the_headers_order_of_joints() -> None:
    names = list(reversed(NAMES))
    traj = parse_csv(
        csv([0, *range(6)], [0.5, *range(1, 7)], header="t_s," + ",".join(names)), "a.csv", NAMES
    )
    np.testing.assert_array_equal(traj.t_s, [0.0, 0.5])
    np.testing.assert_array_equal(traj.q_rad[0], [5, 4, 3, 2, 1, 0])


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("", "a.csv: empty: a trajectory is a CSV with the header t_s,shoulder_pan_joint,"),
        (csv([0] * 7, header="t,a"), "a.csv:1: the header is t,a; want t_s and each joint"),
        (csv([0] * 7, header=HEADER.replace("elbow_joint", "shoulder_pan_joint")), "a.csv:1: the header is"),
        (csv([0] * 7), "a.csv: 1 points: a trajectory has 2 to 100000"),
        (csv([0] * 7, [1] * 6), "a.csv:3: 6 values, the header names 7"),
        (
            csv([0] * 7, [1, 0, 0, "nan", 0, 0, 0]),
            "a.csv:3: elbow_joint = 'nan' is not a finite number",
        ),
        (csv([0.1] + [0] * 6, [1] * 7), "a.csv:2: the first point's t_s is 0.1: a trajectory starts at 0"),
        (csv([0] * 7, [1] * 7, [1] * 7), "a.csv:4: t_s = 1 after 1: the times must increase strictly"),
    ],
)
def test_a_malformed_csv_is_refused_naming_the_line(text: str, error: str) -> None:
    with pytest.raises(CommandError) as e:
        parse_csv(text, "a.csv", NAMES)
    assert str(e.value).startswith(error), str(e.value)


def test_a_trajectory_is_checked_whole_and_from_where_the_arm_is() -> None:
    t = np.array([0.0, 1.0, 2.0])
    q = np.tile(HOME, (3, 1))
    q[1, 4] += 0.5
    check_trajectory(CFG, JointTrajectory(t, q), "ok.csv", HOME)
    with pytest.raises(
        CommandError, match=r"ok.csv: the trajectory starts 0.02 rad from where joint elbow_joint is"
    ):
        check_trajectory(
            CFG, JointTrajectory(t, q), "ok.csv", [h + 0.02 * (i == 2) for i, h in enumerate(HOME)]
        )
    fast = JointTrajectory(t * 0.1, q)
    with pytest.raises(
        CommandError, match=r"fast.csv: row 1 to 2 \(t_s = 0\): wrist_2_joint's velocity reaches 7.5 rad/s, "
    ):
        check_trajectory(CFG, fast, "fast.csv", HOME)
    long = JointTrajectory(t * 200.0, q)
    with pytest.raises(
        CommandError, match=r"long.csv: lasts 400 s; a task may run 300 s \(daemon.task_timeout_s\)"
    ):
        check_trajectory(CFG, long, "long.csv", HOME)


@pytest.mark.parametrize("kind", ["move", "follow"])
def test_the_written_mission_passes_every_check_and_builds_on_the_robot(kind: str, tmp_path: Path) -> None:
    task = ROOT / "configs/tasks" / ("move_joints.toml" if kind == "move" else "follow_joints.toml")
    sets = ["traj.target_rad = [0.0, -1.5, 1.5, -1.5, -1.5, 0.0]"] if kind == "move" else []
    path = tmp_path / "adhoc.mission"
    path.write_text(mission_text(kind, kind.capitalize(), "arm", task, sets))
    automaton, report = check_mission(path)
    assert report.ok, report.format()
    built = check_on_robot(automaton, [create_resource(CFG)], "ur5e")
    if kind == "move":
        assert built.ok, built
    else:  # a file alone cannot give the follower its points: only the daemon can
        assert not built.ok and "plays data the daemon gives it" in built.summary, built


def stand_in(modes: set[CommandMode], held_in: CommandMode) -> Any:
    """What `mode_for` reads of a unit: its resource's modes, its Hold task's."""
    resource = SimpleNamespace(description=SimpleNamespace(modes=frozenset(modes)))
    hold = SimpleNamespace(signature=SimpleNamespace(command=held_in))
    return SimpleNamespace(name="arm", resource=resource, loop=SimpleNamespace(hold=hold))


def test_the_mode_is_the_hold_tasks_else_torque_else_position() -> None:
    P, V, TQ = CommandMode.POSITION, CommandMode.VELOCITY, CommandMode.TORQUE
    assert mode_for(stand_in({P, TQ}, P)) is P  # a UR over RTDE, a CANopen drive: held by servoJ, CSP
    assert mode_for(stand_in({P, TQ}, TQ)) is TQ  # the simulated arm
    assert mode_for(stand_in({P, V}, V)) is P
    with pytest.raises(CommandError, match="resource arm takes neither torque nor position commands"):
        mode_for(stand_in({V}, V))
    assert task_file(StationConfig.of(CFG), "move", P).name == "move_joints_csp.toml"
    assert task_file(StationConfig.of(CFG), "follow", TQ) == ROOT / "configs/tasks/follow_joints.toml"


def test_a_pose_outside_the_workspace_is_refused_before_anything_moves(tmp_path: Path) -> None:
    boxed = tmp_path / "boxed.toml"
    text = UR5E.read_text().replace('"../', f'"{UR5E.parent.parent}/')
    text = text.replace("\n[daemon]\n", f'\n[daemon]\ntask_dirs = ["{ROOT}/configs/tasks"]\n', 1)
    boxed.write_text(
        text.replace(
            "[safe_stop]",
            "[workspace]\nbox_min_m = [-1.0, -1.0, 0.1]\nbox_max_m = [0.0, 1.0, 1.0]\n\n[safe_stop]",
        )
    )
    cfg = load_robot_config(boxed)
    res = create_resource(cfg)
    unit = SimpleNamespace(
        name="arm",
        resource=res,
        cfg=cfg,
        loop=SimpleNamespace(hold=SimpleNamespace(signature=SimpleNamespace(command=CommandMode.TORQUE))),
    )
    machine = SimpleNamespace(units=[unit], station=StationConfig.of(cfg))
    with pytest.raises(
        CommandError,
        match=r"move: the pose's position \(0.2, 0, 0.5\) m is outside the workspace "
        r"\(\[workspace\] in .*boxed.toml\)",
    ):
        move_pose(machine, [0.2, 0.0, 0.5], "", 0.5)  # type: ignore[arg-type]
    job = move_pose(machine, [-0.4, 0.1, 0.5, 3.14159, 0.0, 0.0], "", 0.5)  # type: ignore[arg-type]
    assert "line.target_position_m = [-0.4, 0.1, 0.5]" in job.text and "T2 OutsideWorkspace" in job.text
    path = tmp_path / "move.mission"
    path.write_text(job.text)
    automaton, report = check_mission(path)
    assert report.ok, report.format()
    assert check_on_robot(automaton, [create_resource(cfg)], "ur5e").ok
