"""orccadd on canopen-2bus (six CiA 402 axes on two buses), everything in its own process: a hub
per bus, one drive simulator on both, orccadd and orccadctl. At 500 Hz here: the drive simulator
(six Pinocchio-simulated axes in Python) beside the controller on two cores does not keep up with
1 kHz when the machine is busy; the 1 kHz figures are `benchmarks/canopen_cycle.py --buses 2`'s."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.canopen_rig import CANOPEN_2BUS, Rig
from tests.daemon.conftest import Daemon
from tests.daemon.test_canopen import rig_and_daemon

MISSION = str(Path(__file__).resolve().parent / "missions/canopen.mission")


@pytest.fixture
def rig_daemon(tmp_path: Path) -> Iterator[tuple[Rig, Daemon]]:
    with rig_and_daemon(tmp_path, robot=CANOPEN_2BUS, period_s=0.002) as rd:
        yield rd


def test_a_mission_with_csp_and_cst_motions_completes_on_two_buses(rig_daemon: tuple[Rig, Daemon]) -> None:
    rig, d = rig_daemon
    r = d.ctl("load", MISSION)
    assert r.returncode == 0, r.stderr
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], s
    q = [j["q_rad"] for j in s["joints"]]
    assert q == pytest.approx([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], abs=0.01)
    assert rig.drives.status()["q_rad"] == pytest.approx(q, abs=0.01)  # the drives of both buses agree
    syncs = rig.drives.status()["bus_syncs"]
    assert syncs["can0"] > 0 and syncs["can1"] > 0


def test_a_drive_fault_on_one_bus_stops_every_axis_then_reset(rig_daemon: tuple[Rig, Daemon]) -> None:
    rig, d = rig_daemon
    d.call("load", path=MISSION)
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach")
    rig.drives.inject("overcurrent", device=3, bus="can1")  # wrist_3_joint
    d.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []), timeout_s=30)
    states = rig.drives.status()["states"]
    assert states[5] == "FAULT" and states[:5] == ["SWITCH_ON_DISABLED"] * 5  # can0's too
    d.call("stop")  # the safe procedure awaits the operator's Stop
    d.wait(lambda s: s["state"] == "ready")
    r = d.ctl("reset")
    assert r.returncode == 0, r.stdout + r.stderr
    d.wait(lambda s: not s["faulted"])
    deadline = time.monotonic() + 5.0  # the Hold task enables every drive again, on both buses
    while (states := rig.drives.status()["states"]) != ["OPERATION_ENABLED"] * 6:
        assert time.monotonic() < deadline, states
        time.sleep(0.05)
