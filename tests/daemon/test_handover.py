"""A hand-over between two arms, each with its gripper (configs/robots/dual-arm-grippers-sim.toml:
four resources, four clocks; configs/missions/handover.mission): the arms' plants in processes of
their own, each gripper's chain on a servo simulator of its own started from the cell's config
(`--resource`), orccadd and its clients. Each step waits for the other side's postcondition."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import pytest

from orccadd.dxlsim.process import DxlSimProcess
from tests.daemon.conftest import ROOT, Daemon, start_daemon_with

CELL = ROOT / "configs/robots/dual-arm-grippers-sim.toml"
MISSION = str(ROOT / "configs/missions/handover.mission")
PART_AT_RAD = 0.9
pytestmark = pytest.mark.timeout(300, method="thread")


@pytest.fixture
def cell(tmp_path: Path) -> Iterator[tuple[DxlSimProcess, DxlSimProcess, Daemon]]:
    with (
        DxlSimProcess(CELL, "--resource", "left_hand", "--priority", "70") as left,
        DxlSimProcess(CELL, "--resource", "right_hand", "--priority", "70") as right,
    ):
        d = start_daemon_with(tmp_path, CELL)
        try:
            yield left, right, d
        finally:
            d.stop()


def run(d: Daemon) -> list[list[str]]:
    d.call("load", path=MISSION)
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=120)
    assert s["result"] == "success" and not s["faulted"], s
    events = cast(list[dict[str, Any]], d.call("events", last=200)["events"])  # type: ignore[index]
    return [sorted(e["inputs"]) for e in events if e["kind"] == "instant" and e["inputs"]]


def test_the_part_goes_from_the_left_hand_to_the_right(
    cell: tuple[DxlSimProcess, DxlSimProcess, Daemon],
) -> None:
    left, right, d = cell
    assert [r["name"] for r in cast(dict[str, Any], d.call("describe"))["resources"]] == [
        "left", "right", "left_hand", "right_hand",
    ]  # fmt: skip
    left.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)  # the part in it
    right.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)  # there to take
    steps = [i for step in run(d) for i in step]
    # the right hand closes only once both arms met; the left lets go only once it is taken
    assert max(steps.index("MeetL.done"), steps.index("MeetR.done")) < steps.index("TakeR.done"), steps
    assert steps.index("TakeR.done") < steps.index("ReleaseL.done") < steps.index("HomeL.done"), steps
    assert abs(left.status()["q_rad"][0] - 0.1) < 0.05  # the left hand open
    assert PART_AT_RAD <= right.status()["q_rad"][0] < PART_AT_RAD + 0.1  # the right holds the part


def test_a_right_hand_closing_on_nothing_leaves_the_part_in_the_left(
    cell: tuple[DxlSimProcess, DxlSimProcess, Daemon],
) -> None:
    left, _, d = cell
    left.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)
    steps = [i for step in run(d) for i in step]
    assert "TakeR.T2.Missed" in steps and "ReleaseL.done" not in steps, steps
    assert PART_AT_RAD <= left.status()["q_rad"][0] < PART_AT_RAD + 0.1  # still held on the left


def test_the_holding_hand_overloaded_while_the_arms_meet_enters_the_safe_procedure(
    cell: tuple[DxlSimProcess, DxlSimProcess, Daemon],
) -> None:
    """The left hand holds the part with the mission's KeepL while the arms meet: its overload is
    KeepL's type 3, the safe procedure runs, the arms and the other hand are held (not stopped),
    and the run ends `safe` on the operator's Stop."""
    left, _, d = cell
    left.inject("object", device=1, at_rad=PART_AT_RAD, stiffness_nm_rad=20.0)
    d.call("load", path=MISSION)
    d.call("start")

    def resources() -> dict[str, dict[str, Any]]:
        return {r["name"]: r for r in cast(dict[str, Any], d.call("describe"))["resources"]}

    d.wait(lambda s: resources()["left_hand"]["task"] == "KeepL", timeout_s=60)
    left.inject("overload", device=1)
    d.wait(lambda s: s["faulted"], timeout_s=30)
    r = resources()
    assert r["left_hand"]["fault"]["resource"] == "left_hand", r["left_hand"]
    assert all(r[x]["fault"] is None for x in ("left", "right", "right_hand")), r
    assert (r["left"]["task"], r["right"]["task"]) == ("Hold_left", "Hold_right"), r
    d.call("send", input="Stop")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=30)
    assert s["result"] == "safe", s
