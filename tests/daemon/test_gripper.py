"""A gripper through orccadd (configs/robots/gripper-sim.toml, configs/missions/grasp.mission):
one DYNAMIXEL servo in current-based position mode on the servo simulator, which places a part
between the fingers on request. Closing on the part is Close's postcondition (grasp_watch: at
rest short of the goal, pressing); closing on nothing is its type 2 Missed (grasp_missed_watch),
handled by opening again."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.dxlsim.process import DxlSimProcess
from tests.daemon.conftest import ROOT, Daemon, start_daemon_with
from tests.daemon.test_dynamixel import dxl_daemon_rig

GRIPPER = ROOT / "configs/robots/gripper-sim.toml"
MISSION = str(ROOT / "configs/missions/grasp.mission")
PART_AT_RAD = 0.9  # where the fingers meet the part (the mission closes toward 1.4)
pytestmark = pytest.mark.timeout(180, method="thread")


@pytest.fixture
def gripper(tmp_path: Path) -> Iterator[tuple[DxlSimProcess, Daemon]]:
    with dxl_daemon_rig(tmp_path, base=GRIPPER) as rig:
        d = start_daemon_with(tmp_path, rig.config)
        try:
            yield rig.sim, d
        finally:
            d.stop()


def run_mission(d: Daemon) -> list[str]:
    """Load and start the grasp mission, wait for its end: its instants' inputs, in order."""
    d.call("load", path=MISSION)
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success" and not s["faulted"], s
    events = d.call("events", last=100)["events"]  # type: ignore[index]
    return [i for e in events if e["kind"] == "instant" for i in e["inputs"]]


def test_closing_on_a_part_is_grasped_and_ends_at_the_part(gripper: tuple[DxlSimProcess, Daemon]) -> None:
    sim, d = gripper
    sim.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)
    inputs = run_mission(d)
    assert inputs == ["Open.done", "Close.done"], inputs
    q = sim.status()["q_rad"][0]
    assert PART_AT_RAD <= q < PART_AT_RAD + 0.1, q  # at the part, not closed past it


def test_closing_on_nothing_is_missed_and_the_gripper_opens_again(
    gripper: tuple[DxlSimProcess, Daemon],
) -> None:
    sim, d = gripper
    inputs = run_mission(d)
    assert inputs == ["Open.done", "Close.T2.Missed", "Open.done"], inputs
    assert abs(sim.status()["q_rad"][0] - 0.1) < 0.05  # open again
