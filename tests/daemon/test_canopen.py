"""orccadd on a CANopen arm, everything in its own process: the bus (userspace hub or vcan0),
the simulated CiA 402 drives, orccadd (real-time process + command daemon) and orccadctl."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.canopen_rig import (
    BusRecorder,
    Rig,
    canopen_rig,
    emcy_errors,
    enable_to_sync_gaps_s,
    nodes_enabled,
    until,
)
from tests.daemon.conftest import Daemon, start_daemon_with

MISSION = str(Path(__file__).resolve().parent / "missions/canopen.mission")


@contextmanager
def rig_and_daemon(tmp_path: Path, **rig: Any) -> Iterator[tuple[Rig, Daemon]]:
    """A CANopen rig (`canopen_rig`'s options) and a daemon on it; both stopped at the end."""
    with canopen_rig(tmp_path, **rig) as r:
        d = start_daemon_with(tmp_path, r.config)
        try:
            yield r, d
        finally:
            d.stop()


@pytest.fixture
def rig_daemon(tmp_path: Path) -> Iterator[tuple[Rig, Daemon]]:
    with rig_and_daemon(tmp_path) as rd:
        yield rd


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
    rig.drives.inject("following_error", device=2)
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


def test_the_daemon_enables_the_drives_once_its_loop_runs(tmp_path: Path) -> None:
    """Issue 15: the daemon activates the arm, then builds its machine for 0.15-0.22 s before the
    loop's first tick. The drives (watching our heartbeat) wait in SWITCHED ON meanwhile, and the
    loop enables them: every Enable Operation is followed by a SYNC well within a heartbeat period
    (the hub's own time stamps), and no drive reports an error. (What comes after the startup is
    the other tests': a drive simulator starved by this loaded VM makes the arm COMM_LOST.)"""
    with canopen_rig(tmp_path) as rig, BusRecorder(rig) as bus:
        d = start_daemon_with(tmp_path, rig.config)
        try:
            deadline = time.monotonic() + 10
            while nodes_enabled(list(bus.frames)) != set(range(1, 7)) and time.monotonic() < deadline:
                time.sleep(0.1)
            time.sleep(0.8)  # past the drives' heartbeat timeout (3 × 200 ms)
            end_s = time.time()
        finally:
            d.stop()
    frames = until(bus.frames, end_s)
    assert nodes_enabled(frames) == set(range(1, 7)), d.log.read_text()
    assert not emcy_errors(frames)
    gaps_s = enable_to_sync_gaps_s(frames)
    assert gaps_s and max(gaps_s) < 0.2, max(gaps_s)  # the rig's controller_heartbeat_ms
