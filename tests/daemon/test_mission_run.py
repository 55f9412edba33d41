"""A verified mission on a running orccadd: switching, recovery, hold/resume, stop, abort, SIGTERM."""

from __future__ import annotations

import time

import numpy as np

from orccadd.wire.schema import H, T, TickLayout
from orccadd.wire.telemetry import RingReader, TelemetryBlock
from tests.daemon.conftest import ROOT, Daemon

DEMO = str(ROOT / "configs/missions/demo.mission")


def ticks_of(d: Daemon) -> np.ndarray:
    desc = d.call("describe")
    assert isinstance(desc, dict)
    tel = TelemetryBlock.attach(str(desc["telemetry"]))
    try:
        return RingReader(tel.ticks, tel.header, H.TICK_HEAD, from_now=False).poll()
    finally:
        tel.close()


def test_demo_mission_recovers_and_every_switch_is_seamless(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    s = daemon.wait(lambda s: s["state"] == "ready", timeout_s=60)
    assert s["result"] == "success", s
    ev = daemon.call("events", last=200)
    assert isinstance(ev, dict)
    instants = [e for e in ev["events"] if e["kind"] == "instant"]
    acts = [a for e in instants for a in e["actions"]]
    assert "start Approach" in acts and "success" in acts
    assert any("Inspect.T2.TrackingLost" in e["inputs"] for e in instants)
    # From the trace: at every switch the outgoing and the incoming law both sent a command in
    # consecutive ticks, and the first command of the new law continues the old one.
    rec = ticks_of(daemon)
    overruns = int(daemon.status()["overruns"])  # read after the records: counts each of theirs
    task, wrote, t = rec[:, T.TASK], rec[:, T.WROTE], rec[:, T.T_S]
    cmd = rec[:, TickLayout(6).cmd]
    switches = np.where(np.diff(task) != 0)[0] + 1
    assert len(switches) >= 6, f"only {len(switches)} switches seen"
    period = 0.002
    # No tick lost: the records are consecutive, released on the deadline grid, and a release
    # more than one period after the previous one follows an overrun the loop counted.
    assert (np.diff(rec[:, 0]) == 1).all(), "a tick record is missing"
    gaps = np.diff(t) / period
    whole = np.round(gaps)
    np.testing.assert_allclose(gaps, whole, atol=1e-6)
    assert whole.min() >= 1
    late = set(np.flatnonzero(whole > 1).tolist())  # gap i: from record i to i + 1
    assert len(late) <= overruns, f"{len(late)} skips, only {overruns} overruns counted"
    # A switch is applied at the start of tick k: an overrun next to one may be the machine's
    # noise, but switching must not make the loop skip periods as a rule.
    lost = [int(k) for k in switches if {k - 1, k} & late]
    assert len(lost) <= len(switches) // 2, f"ticks skipped around the switches at {lost}"
    steps = np.abs(np.diff(cmd, axis=0)).max(axis=1)
    typical = float(np.percentile(steps[wrote[1:] > 0], 99.9))
    for k in switches:
        assert wrote[k - 1] and wrote[k], f"tick {k}: a switch left a tick without a command"
        jump = float(np.abs(cmd[k] - cmd[k - 1]).max())
        assert jump <= max(typical, 1.0), (
            f"switch at tick {k}: command jumped {jump:.2f} N.m (typical {typical:.2f})"
        )


def test_hold_resume_stop(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach")
    daemon.call("hold")
    s = daemon.wait(lambda s: s["active_task"] == "Hold" and s["state"] == "holding")
    time.sleep(0.5)
    q1 = [j["q_rad"] for j in daemon.status()["joints"]]  # type: ignore[index]
    time.sleep(0.5)
    q2 = [j["q_rad"] for j in daemon.status()["joints"]]  # type: ignore[index]
    assert np.abs(np.subtract(q1, q2)).max() < 2e-3, "the arm moved while holding"
    daemon.call("resume")
    daemon.wait(lambda s: s["state"] == "running" and s["active_task"] in ("Reach", "Inspect", "Approach"))
    r = daemon.call("stop")
    assert isinstance(r, dict) and r["stopped"]
    s = daemon.wait(lambda s: s["state"] == "ready" and s["active_task"] == "Hold")
    assert s["result"] == "success" and not s["faulted"]
    # another mission loaded: the first run's trace keeps the names of the mission it came from
    daemon.call("load", path=str(ROOT / "configs/missions/demo_position.mission"))
    ev = daemon.call("events", last=500)
    assert isinstance(ev, dict)
    instants = [e for e in ev["events"] if e["kind"] == "instant"]
    assert instants and {e["mission"] for e in instants} == {"PickDemo"}, instants
    assert any("start Reach" in e["actions"] for e in instants)


def test_abort_safe_stops_and_reset_recovers(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach")
    daemon.call("abort")
    s = daemon.wait(lambda s: "stopped" in s.get("resource_status", []))
    assert s["faulted"] and s["result"] == "aborted" and s["state"] == "ready"
    r = daemon.reply("start")
    assert not r["ok"] and "reset" in str(r["error"])
    abort = {"event": "", "kind": "abort", "resource": "arm", "joint": "", "code": 0}
    assert s["fault"] == {**abort, "text": "aborted by the operator"}, s["fault"]  # typed: what, where, why
    daemon.call("reset")
    s = daemon.wait(lambda s: not s["faulted"] and s["task_phase"] == "run")
    r = daemon.call("start")
    assert r == {"started": "PickAndInspect", "mission": "PickDemo", "run": 2}
    daemon.wait(lambda s: s["active_task"] == "Home")
    # a second fault, with no status read between the reset and it: told in its own words
    daemon.call("abort")
    daemon.wait(lambda s: "stopped" in s.get("resource_status", []))
    daemon.call("reset")
    daemon.call("start")
    daemon.call("inject", fault="resource")
    s = daemon.wait(lambda s: s["faulted"])
    assert s["fault"]["event"] == "Home.T3.ResourceFault" and s["fault"]["kind"] == "device", s["fault"]
    events = daemon.call("events", last=20)["events"]  # type: ignore[index]
    [cause] = [e["fault"] for e in events if e["kind"] == "fault"][-1:]
    assert cause["n"] == 3 and cause["text"] == "injected fault", cause  # the run's third safe stop


def test_sigterm_mid_motion_safe_stops_and_exits_cleanly(daemon: Daemon) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach" and max(abs(j["dq_rad_s"]) for j in s["joints"]) > 0.1)  # type: ignore[union-attr]
    assert daemon.stop() == 0
    log = daemon.log.read_text()
    assert "safe stop first" in log and "arm at rest, hardware released" in log, log
