"""Faults injected into a running orccadd; each ends in a defined safe state."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np

from orccadd.physres.shm_channel import Ctl, PlantChannel
from orccadd.types import Status
from tests.daemon.conftest import ROOT, Daemon, start_daemon

DEMO = str(ROOT / "configs/missions/demo.mission")


def _moving(s: dict[str, object]) -> bool:
    return max(abs(j["dq_rad_s"]) for j in s["joints"]) > 0.1  # type: ignore[attr-defined]


def test_consecutive_overruns_raise_type_3_and_the_safe_procedure(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach")
    # each tick takes 1.5 periods: real overruns, more in a row than sim-ur5e's overrun_limit (25)
    daemon.call("inject", fault="overrun", ticks=60)
    s = daemon.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []))
    ev = daemon.call("events", last=30)
    inputs = [i for e in ev["events"] if e["kind"] == "instant" for i in e["inputs"]]  # type: ignore[index]
    assert "Reach.T3.Overrun" in inputs
    acts = [a for e in ev["events"] if e["kind"] == "instant" for a in e["actions"]]  # type: ignore[index]
    assert "safe" in acts
    assert s["state"] == "running"  # the safe procedure awaits the operator's Stop
    daemon.call("stop")
    s = daemon.wait(lambda s: s["state"] == "ready")
    assert s["result"] == "safe"


def test_resource_fault_raises_type_3_then_reset_and_move_again(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach" and _moving(s))
    daemon.call("inject", fault="resource")
    daemon.wait(lambda s: "stopped" in s.get("resource_status", []))
    ev = daemon.call("events", last=30)
    inputs = [i for e in ev["events"] if e["kind"] == "instant" for i in e["inputs"]]  # type: ignore[index]
    assert "Reach.T3.ResourceFault" in inputs
    daemon.call("stop")
    daemon.wait(lambda s: s["state"] == "ready")
    daemon.call("reset")
    daemon.wait(lambda s: not s["faulted"])
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Home" and _moving(s))


def test_command_daemon_killed_mission_goes_on_and_a_new_one_attaches(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    pid = int(daemon.call("ping")["pid"])  # type: ignore[index]
    daemon.wait(lambda s: s["active_task"] == "Reach")
    os.kill(pid, signal.SIGKILL)
    time.sleep(0.5)
    # a new command daemon is started by orccadd and attaches; the mission carried on meanwhile
    end = time.monotonic() + 30
    while True:
        try:
            new = int(daemon.call("ping")["pid"])  # type: ignore[index]
            if new != pid:
                break
        except Exception:
            pass
        assert time.monotonic() < end, daemon.log.read_text()
        time.sleep(0.2)
    # started by the SCHED_FIFO automaton thread, it must not inherit a real-time priority
    assert os.sched_getscheduler(new) == os.SCHED_OTHER
    s = daemon.wait(lambda s: s["state"] == "ready", timeout_s=60)
    assert s["result"] == "success" and not s["faulted"]


def test_command_daemon_loss_safe_stops_when_configured(tmp_path: Path) -> None:
    d = start_daemon(tmp_path, daemon_cfg='on_command_daemon_loss = "safe_stop"')
    try:
        d.call("load", path=DEMO)
        d.call("start")
        pid = int(d.call("ping")["pid"])  # type: ignore[index]
        d.wait(lambda s: s["active_task"] == "Reach")
        os.kill(pid, signal.SIGKILL)
        time.sleep(2.0)
        s = d.wait(lambda s: s["faulted"])
        assert s["result"] == "aborted"
    finally:
        d.stop()


def test_realtime_process_killed_the_arm_stops(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach" and _moving(s))
    plant_pid = int(daemon.status()["helper_pid"])  # type: ignore[arg-type]
    shm = daemon.call("describe")["resource"]["diagnostics"]["details"]["plant_channel"]  # type: ignore[index]
    ch = PlantChannel(6, name=str(shm))
    daemon.proc.kill()  # SIGKILL: no safe stop from the controller
    daemon.proc.wait()
    buf = np.zeros(1 + 3 * 6)
    end = time.monotonic() + 10
    stopped = False
    while time.monotonic() < end:
        ch.read_state(buf)
        if int(ch.ctl[Ctl.STATUS]) & Status.STOPPED and np.abs(buf[7:13]).max() < 1e-3:
            stopped = True
            break
        time.sleep(0.02)
    ch.close()
    assert stopped, "the simulated arm did not stop after the controller died"
    end = time.monotonic() + 10
    while time.monotonic() < end:  # once at rest, the plant process exits on its own
        try:
            os.kill(plant_pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.kill(plant_pid, signal.SIGKILL)
        raise AssertionError("the plant process outlived its controller")
