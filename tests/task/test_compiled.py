"""The compiled tick against the interpreted one: the same run through both gives bit-identical
commands and the same events in the same ticks, with kernel modules, with a module that has no
kernel (`low_pass`, called through its ports), with a tune and a new target mid-run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orccadd.errors import ConfigError
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.task import RobotTask
from tests.conftest import MOVE_TASK, PANDA, ROOT, UR5E

FRACTIONS = (0.45, 0.55)  # two targets, as fractions of each joint's range
LOW_PASS = (
    ('"arm.dq -> limits.dq",', '"arm.dq -> lp.x",\n  "lp.y -> limits.dq",'),
    ("[modules.limits]", '[modules.lp]\ntype = "low_pass"\ncutoff_hz = 5.0\n\n[modules.limits]'),
)


def record(
    robot: Path, task_file: Path, compiled: bool, ticks: int
) -> tuple[np.ndarray, list[tuple[int, str]]]:
    s = Session.open(robot)
    task = s.task(task_file)
    if not compiled:
        task.compiled = None
    traj = next(m for m in task.modules if m.name == "traj")
    m = s.resource.model
    dof = m.dof
    targets = [(m.q_min_rad + f * (m.q_max_rad - m.q_min_rad)).tolist() for f in FRACTIONS]
    traj.configure({"target_rad": targets[0]})
    loop = s.loop(SimClock(), overrun_limit=10**6)
    task.activate()
    loop.active = task
    commands = np.zeros((ticks, dof))
    events: list[tuple[int, str]] = []
    for k in range(ticks):
        if k == ticks // 3:
            task.tune("traj.target_rad", targets[1])
            task.tune("ct.kp", 500.0)
        loop.executor.run(max_ticks=1)
        commands[k] = task.sent
        events += [(k, s.registry.info(eid).name) for _, eid in s.queue.drain()]
    s.close()
    return commands, events


def check_same(robot: Path, task_file: Path, ticks: int) -> None:
    c_cmd, c_ev = record(robot, task_file, True, ticks)
    i_cmd, i_ev = record(robot, task_file, False, ticks)
    assert np.isfinite(c_cmd).all() and np.abs(c_cmd).max() > 0  # a real run, commands sent
    assert np.array_equal(c_cmd.view(np.uint64), i_cmd.view(np.uint64))  # bit for bit
    assert c_ev == i_ev and c_ev, c_ev


@pytest.mark.parametrize("robot", [UR5E, PANDA], ids=["ur5e", "panda"])
def test_compiled_and_interpreted_ticks_command_the_same_bits(robot: Path) -> None:
    check_same(robot, MOVE_TASK, 1500)


def test_a_module_without_a_kernel_runs_through_its_ports_in_the_compiled_tick(task_variant) -> None:  # type: ignore[no-untyped-def]
    path = task_variant(*LOW_PASS)
    task: RobotTask = Session.open(UR5E).task(path)
    assert task.compiled_tick is not None
    source = task.compiled_tick.source
    assert "update" in source and source.count("kernel") == len(task.modules) - 1, source
    check_same(UR5E, path, 1500)


def test_the_robot_config_chooses_the_interpreted_tick(robot_variant) -> None:  # type: ignore[no-untyped-def]
    path = robot_variant(("\n[daemon]\n", '\n[daemon]\ntick = "interpreted"\n'))
    assert Session.open(path).task(MOVE_TASK).compiled is None
    assert Session.open(UR5E).task(MOVE_TASK).compiled is not None
    bad = robot_variant(("\n[daemon]\n", '\n[daemon]\ntick = "jit"\n'))
    with pytest.raises(ConfigError) as e:
        Session.open(bad)
    assert "daemon.tick" in str(e.value) and "'jit'" in str(e.value) and "interpreted" in str(e.value)


def test_the_benchmarks_two_laws_ten_watchers_task_is_the_same_compiled() -> None:
    check_same(UR5E, ROOT / "benchmarks/tasks/two_laws_ten_watchers.toml", 1000)
