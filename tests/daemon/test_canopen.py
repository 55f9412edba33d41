"""orccadd on a CANopen arm, everything in its own process: the bus (userspace hub or vcan0),
the simulated CiA 402 drives, orccadd (real-time process + command daemon) and orccadctl."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.canopen_rig import Rig, canopen_rig
from tests.daemon.conftest import Daemon, start_daemon_with

MISSION = str(Path(__file__).resolve().parent / "missions/canopen.mission")


@pytest.fixture
def rig_daemon(tmp_path: Path) -> Iterator[tuple[Rig, Daemon]]:
    with canopen_rig(tmp_path) as rig:
        d = start_daemon_with(tmp_path, rig.config)
        try:
            yield rig, d
        finally:
            d.stop()


def test_a_mission_with_csp_and_cst_motions_completes(rig_daemon: tuple[Rig, Daemon]) -> None:
    rig, d = rig_daemon
    r = d.ctl("load", MISSION)
    assert r.returncode == 0, r.stderr
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], s
    ev = d.call("events", last=60)
    acts = [a for e in ev["events"] if e["kind"] == "instant" for a in e["actions"]]  # type: ignore[index]
    assert {"start Home", "start Reach", "start Track", "start Settle"} <= set(acts), acts
    q = [j["q_rad"] for j in s["joints"]]
    # Track (CST, computed torque) reached its target and Settle (CST, PD + gravity) held it 1 s
    assert q == pytest.approx([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], abs=0.01)
    assert rig.drives.status()["q_rad"] == pytest.approx(q, abs=0.01)  # the drives agree
    # then the Hold task (CSP: the drives' position loops) keeps the arm where it is
    time.sleep(1.0)
    held = [j["q_rad"] for j in d.status()["joints"]]
    assert held == pytest.approx(q, abs=0.01)


def test_drive_fault_type_3_quick_stop_then_reset_through_orccadctl(rig_daemon: tuple[Rig, Daemon]) -> None:
    rig, d = rig_daemon
    d.call("load", path=MISSION)
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach")
    rig.drives.inject(2, "following_error")
    s = d.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []), timeout_s=30)
    states = rig.drives.status()["states"]
    assert states[1] == "FAULT" and all(st in ("SWITCH_ON_DISABLED", "FAULT") for st in states)
    ev = d.call("events", last=40)
    inputs = [i for e in ev["events"] if e["kind"] == "instant" for i in e["inputs"]]  # type: ignore[index]
    assert any(i.startswith("Reach.T3.") for i in inputs), inputs
    d.call("stop")  # the safe procedure awaits the operator's Stop
    d.wait(lambda s: s["state"] == "ready")
    r = d.ctl("reset")
    assert r.returncode == 0, r.stdout + r.stderr
    s = d.wait(lambda s: not s["faulted"])
    assert rig.drives.status()["states"] == ["OPERATION_ENABLED"] * 6
    d.call("start")  # and a new motion: Home and Reach (CSP) complete, Track starts
    s = d.wait(lambda s: s["active_task"] == "Track" or s["faulted"] or s["state"] != "running", 60)
    assert s["active_task"] == "Track" and not s["faulted"], s["fault"]
    d.call("abort")
