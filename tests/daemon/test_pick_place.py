"""An arm and its gripper in one daemon (configs/robots/ur5e-gripper-sim.toml): the UR controller
simulator and the servo simulator, each its own process serving its own bus's resource from the
cell's config, orccadd and its clients; configs/missions/pick_place.mission run through them.
Faults across resources: one resource's fault holds the other."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import pytest

from orccadd.dxlsim.process import DxlSimProcess
from orccadd.ursim.process import UrSimProcess
from tests.daemon.conftest import ROOT, Daemon, start_daemon_with

CELL = ROOT / "configs/robots/ur5e-gripper-sim.toml"
MISSION = str(ROOT / "configs/missions/pick_place.mission")
PART_AT_RAD = 0.9  # where the fingers meet the part (Close closes toward 1.4)
pytestmark = pytest.mark.timeout(300, method="thread")


@dataclass
class Cell:
    ur: UrSimProcess
    gripper: DxlSimProcess
    d: Daemon

    def resources(self) -> dict[str, dict[str, Any]]:
        return {r["name"]: r for r in cast(dict[str, Any], self.d.call("describe"))["resources"]}

    def inputs(self) -> list[str]:
        events = cast(list[dict[str, Any]], self.d.call("events", last=200)["events"])  # type: ignore[index]
        return [i for e in events if e["kind"] == "instant" for i in e["inputs"]]

    def run_until(self, task: str, resource: str = "arm") -> None:
        self.d.call("load", path=MISSION)
        self.d.call("start")
        self.d.wait(lambda s: self.resources()[resource]["task"] == task, timeout_s=60)


@pytest.fixture
def cell(tmp_path: Path) -> Iterator[Cell]:
    with (
        UrSimProcess(CELL, "--boot", "running", "--priority", "70") as ur,
        DxlSimProcess(CELL, "--priority", "70") as gripper,
    ):
        d = start_daemon_with(tmp_path, CELL)
        try:
            yield Cell(ur, gripper, d)
        finally:
            d.stop()


def test_the_arm_picks_and_places_the_part(cell: Cell) -> None:
    r = cell.resources()
    assert (r["arm"]["clock"], r["arm"]["period_s"]) == ("device", 0.002)  # the controller's stream
    assert (r["gripper"]["clock"], r["gripper"]["period_s"]) == ("loop", 0.005)
    cell.gripper.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)
    cell.d.call("load", path=MISSION)
    cell.d.call("start")
    s = cell.d.wait(lambda s: s["state"] != "running", timeout_s=120)
    assert s["result"] == "success" and not s["faulted"], s
    inputs = cell.inputs()
    assert inputs[:2] in (["Open.done", "Above.done"], ["Above.done", "Open.done"]), inputs  # at once
    assert inputs[2:] == [
        "Down.done", "Close.done", "Lift.done", "Over.done", "Place.done", "Release.done", "Retreat.done",
    ]  # fmt: skip
    assert abs(cell.gripper.status()["q_rad"][0] - 0.1) < 0.05  # released: open again


def test_closing_on_nothing_opens_retreats_and_ends_without_a_part(cell: Cell) -> None:
    cell.d.call("load", path=MISSION)
    cell.d.call("start")
    s = cell.d.wait(lambda s: s["state"] != "running", timeout_s=120)
    assert s["result"] == "success" and not s["faulted"], s
    inputs = cell.inputs()
    assert inputs[2:] == ["Down.done", "Close.T2.Missed", "Open.done", "Retreat.done"], inputs


def test_a_gripper_fault_while_the_arm_moves_holds_the_arm(cell: Cell) -> None:
    """The gripper holds the part with the mission's Grip while the arm carries it: its overload is
    Grip's type 3, the mission's `on fatal` enters the safe procedure (which opens nothing), the
    arm is held where it is, and the run ends `safe` on the operator's Stop."""
    cell.gripper.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)
    cell.run_until("Over")
    assert cell.resources()["gripper"]["task"] == "Grip"  # the mission's, not the daemon's Hold
    cell.gripper.inject("overload", device=1)  # the servo's hardware error: torque off
    cell.d.wait(lambda s: s["faulted"] and "Grip.T3.ResourceFault" in cell.inputs(), timeout_s=30)
    r = cell.resources()
    assert r["gripper"]["fault"]["resource"] == "gripper", r["gripper"]
    assert r["arm"]["fault"] is None and r["arm"]["task"] == "Hold_arm", r["arm"]  # held, not stopped
    assert not cell.ur.status()["devices"][0]["fault"]  # the controller: no protective stop
    cell.d.call("send", input="Stop")  # the operator's acknowledgement ends the safe procedure
    s = cell.d.wait(lambda s: s["state"] != "running", timeout_s=30)
    assert s["result"] == "safe", s


def test_the_arms_link_lost_while_the_gripper_closes_holds_the_gripper(cell: Cell) -> None:
    cell.gripper.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)
    cell.run_until("Close", resource="gripper")
    # the arm (held meanwhile) loses its controller's stream: stalled for 2 s (a dropped
    # connection sets ur_rtde's clients reconnecting from their own threads, and that has crashed
    # the process: docs/status.md, UR RTDE)
    cell.ur.inject("stream_stall", duration_s=2.0)
    # no task of the mission on the arm: its fault is the mission's `arm.fault`, the safe procedure
    cell.d.wait(lambda s: s["faulted"] and "arm.fault" in cell.inputs(), timeout_s=30)
    r = cell.resources()
    assert r["arm"]["fault"]["resource"] == "arm", r["arm"]
    assert r["gripper"]["fault"] is None and r["gripper"]["task"] == "Hold_gripper", r["gripper"]
    time.sleep(3.0)  # the stream back meanwhile: the arm stays stopped (its links dropped) until reset
    assert cell.d.status()["state"] == "running" and cell.resources()["arm"]["fault"]
    cell.d.call("send", input="Stop")  # the operator's acknowledgement ends the safe procedure
    s = cell.d.wait(lambda s: s["state"] != "running", timeout_s=30)
    assert s["result"] == "safe" and s["faulted"], s
