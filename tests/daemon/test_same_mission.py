"""The same position-mode mission (configs/missions/demo_position.mission) on every backend
(sim-ur5e, canopen-6axis in CSP, ur5e-rtde-sim by servoJ, dxl-6axis-sim: a smaller arm with
other joint limits, ethercat-6axis-sim in CSP at 1 kHz), through orccadd and orccadctl, each in
its own processes: it runs to completion and its reactive trace (the instants: states, inputs,
actions) is the same whatever the arm."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from orccadd.ecatsim.process import EcatSimProcess
from orccadd.ursim.process import UrSimProcess
from tests.canopen_rig import canopen_rig
from tests.daemon.conftest import ROOT, Daemon, robot_config, start_daemon_with
from tests.daemon.test_dynamixel import dxl_daemon_rig

MISSION = str(ROOT / "configs/missions/demo_position.mission")
UR = ROOT / "configs/robots/ur5e-rtde-sim.toml"
ECAT = ROOT / "configs/robots/ethercat-6axis-sim.toml"


def local_config(tmp: Path, source: Path) -> Path:
    """`source` with its relative paths made absolute and the test's mission directory allowed."""
    text = source.read_text().replace('"../', f'"{source.parent.parent}/')
    if "task_dirs" not in text:  # its default, ../tasks, is relative to the config too
        text = text.replace("\n[daemon]\n", f'\n[daemon]\ntask_dirs = ["{source.parent.parent}/tasks"]\n', 1)
    path = tmp / source.name
    path.write_text(text)
    return path


def run_mission(d: Daemon) -> list[tuple[int, int, tuple[str, ...], tuple[str, ...]]]:
    r = d.ctl("load", MISSION)
    assert r.returncode == 0, r.stderr
    r = d.ctl("start")
    assert r.returncode == 0, r.stderr
    s = d.wait(lambda s: s["state"] != "running", timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], s
    events = d.call("events", last=100)["events"]  # type: ignore[index]
    return [
        (e["from"], e["to"], tuple(e["inputs"]), tuple(e["actions"]))
        for e in events
        if e["kind"] == "instant"
    ]


@contextmanager
def arm_config(backend: str, tmp: Path) -> Iterator[Path]:
    """The robot config orccadd runs on for `backend`, with its device simulator running."""
    if backend == "sim":
        yield robot_config(tmp)
    elif backend == "canopen402":
        with canopen_rig(tmp) as rig:
            yield rig.config
    elif backend == "ur_rtde":
        with UrSimProcess(UR, "--boot", "running", "--priority", "70"):
            yield local_config(tmp, UR)
    elif backend == "ethercat402":
        with EcatSimProcess(ECAT, "--priority", "70"):
            yield local_config(tmp, ECAT)
    else:  # dxl-6axis-sim: the servo simulator on a pseudo-terminal under tmp
        with dxl_daemon_rig(tmp) as rig:
            yield rig.config


@pytest.fixture(params=["sim", "canopen402", "ur_rtde", "dynamixel", "ethercat402"])
def backend_daemon(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Daemon]:
    with arm_config(request.param, tmp_path) as config:
        d = start_daemon_with(tmp_path, config)
        try:
            yield d
        finally:
            d.stop()  # before the simulator goes


EXPECTED = [
    (0, 1, (), ("start Home",)),
    (1, 3, ("Home.done",), ("stop Home", "start Reach")),
    (3, 5, ("Reach.done",), ("stop Reach", "start Back")),
    (5, 2, ("Back.done",), ("stop Back", "success")),
]


@pytest.mark.timeout(300, method="thread")
def test_the_position_mission_runs_with_the_same_reactive_trace_on_every_backend(
    backend_daemon: Daemon,
) -> None:
    assert run_mission(backend_daemon) == EXPECTED
