"""orccadd on a UR arm, everything in its own process: the UR controller simulator (stock ur_rtde
protocols), orccadd (real-time process + command daemon) and orccadctl. The controller's own
stops end in the mission's safe procedure and `orccadctl reset` recovers what a command may; a
controller that dies is CommLost at once, and `reset` reconnects once it is back."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from orccadd.types import Status
from orccadd.ursim.process import UrSimProcess
from tests.daemon.conftest import ROOT, Daemon, moving, start_daemon_with
from tests.daemon.test_same_mission import local_config
from tests.safety import assert_commands_within_limits, assert_safe_stop_in_time, from_telemetry, status_shows

UR = ROOT / "configs/robots/ur5e-rtde-sim.toml"
MISSION = str(ROOT / "configs/missions/demo_position.mission")
SIM_ARGS = ("--boot", "running", "--unlock-delay-s", "1", "--priority", "70")

# ur_rtde blocks in C++ holding the interpreter: only a thread can time such a test out
pytestmark = pytest.mark.timeout(180, method="thread")


@pytest.fixture
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(UR, *SIM_ARGS) as s:
        yield s


@pytest.fixture
def daemon(sim: UrSimProcess, tmp_path: Path) -> Iterator[Daemon]:
    d = start_daemon_with(tmp_path, local_config(tmp_path, UR))
    try:
        yield d
    finally:
        d.stop()  # ur_rtde's clients go before the simulator does


def telemetry(d: Daemon) -> str:
    return str(d.call("describe")["telemetry"])  # type: ignore[index]


def tick_gaps(d: Daemon) -> str:
    """The longest gaps between the ring's ticks (a failure's evidence: a stalled loop)."""
    ticks = from_telemetry(telemetry(d))
    gaps = np.diff(ticks.t_s)
    worst = np.argsort(gaps)[-5:][::-1]
    return "longest tick gaps: " + ", ".join(f"{gaps[i] * 1e3:.0f} ms at {ticks.t_s[i]:.3f}" for i in worst)


def t3_inputs(d: Daemon) -> list[str]:
    """The type 3 inputs of the run, without the task's name: the fault is injected while the
    arm moves, in Reach or, on a loaded machine, in Back (a motion as well)."""
    ev = d.call("events", last=60)
    names = [i for e in ev["events"] if e["kind"] == "instant" for i in e["inputs"] if ".T3." in i]  # type: ignore[index]
    assert all(n.split(".")[0] in ("Reach", "Back") for n in names), names
    return [n.split(".", 1)[1] for n in names]


def t3_trace(d: Daemon) -> list[str]:
    """Every type 3 in the trace: the automaton's inputs and the events it does not see (the
    Hold task's), full names."""
    ev = d.call("events", last=200)["events"]
    out: list[str] = []
    for e in ev:  # type: ignore[union-attr]
        if e["kind"] == "instant":
            out += [i for i in e["inputs"] if ".T3." in i]
        elif e["kind"] == "event" and ".T3." in e["event"]:
            out.append(e["event"])
    return out


def start_mission_until_reach(d: Daemon) -> None:
    r = d.ctl("load", MISSION)
    assert r.returncode == 0, r.stderr
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach" and moving(s), timeout_s=30)  # mid-motion


def acknowledge(d: Daemon) -> None:
    """The safe procedure awaits the operator's Stop."""
    s = d.status()
    assert s["state"] == "running", s
    d.call("stop")
    s = d.wait(lambda s: s["state"] == "ready")
    assert s["result"] == "safe", s


def run_to_success(d: Daemon) -> None:
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], s


def test_protective_stop_mid_motion_safe_procedure_then_orccadctl_reset_and_a_new_run(
    sim: UrSimProcess, daemon: Daemon
) -> None:
    start_mission_until_reach(daemon)
    sim.inject("protective_stop")
    s = daemon.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []), timeout_s=20)
    assert "safety mode PROTECTIVE_STOP" in str(s["fault"]), s["fault"]
    assert t3_inputs(daemon) == ["T3.ResourceFault"]
    ticks = from_telemetry(telemetry(daemon))
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.FAULT))
    assert_commands_within_limits(ticks, UR)
    acknowledge(daemon)
    deadline = time.monotonic() + 15
    while True:  # the controller allows the unlock 1 s after the stop (here; 5 s on a real one)
        r = daemon.ctl("reset")
        if r.returncode == 0:
            break
        assert "Cannot unlock protective stop" in r.stderr and time.monotonic() < deadline, r.stderr
        time.sleep(0.3)
    daemon.wait(lambda s: not s["faulted"] and not s.get("resource_status"))
    # one stop, one type 3: not the Hold task's again on a controller still protective-stopped
    assert [n.split(".", 1)[1] for n in t3_trace(daemon)] == ["T3.ResourceFault"], t3_trace(daemon)
    st = sim.status()
    assert st["safety_mode"] == "NORMAL" and st["runtime_state"] == "PLAYING", st
    run_to_success(daemon)


def test_an_emergency_stop_is_a_type_3_and_reset_says_what_the_pendant_needs(
    sim: UrSimProcess, daemon: Daemon
) -> None:
    start_mission_until_reach(daemon)
    sim.inject("emergency_stop")
    s = daemon.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []), timeout_s=20)
    assert "EMERGENCY_STOP" in str(s["fault"]), s["fault"]
    acknowledge(daemon)
    r = daemon.ctl("reset")
    assert r.returncode != 0
    assert "release the emergency stop button" in r.stderr, r.stderr
    assert daemon.status()["faulted"]  # nothing cleared, the daemon carries on
    sim.inject("emergency_stop_release")


def test_a_dropped_connection_is_comm_lost_and_the_daemon_runs_on_to_a_new_run(
    sim: UrSimProcess, daemon: Daemon
) -> None:
    """The controller drops every connection and takes new ones: ur_rtde, reconnecting from its
    own threads, crashed the daemon within a second (issue 31); in its link process it takes
    only that process down. CommLost, the safe procedure, `reset` starts a new link process."""
    start_mission_until_reach(daemon)
    sim.inject("drop_connection", ports="all")
    s = daemon.wait(lambda s: s["faulted"] and "comm_lost" in s.get("resource_status", []), timeout_s=10)
    assert s["fault"]["kind"] == "comm_lost", s["fault"]
    assert t3_inputs(daemon) == ["T3.CommLost"], daemon.log.read_text()[-3000:]
    daemon.wait(lambda s: "stopped" in s.get("resource_status", []), timeout_s=10)
    time.sleep(1.0)  # where ur_rtde's threads crashed the daemon
    assert daemon.proc.poll() is None, daemon.log.read_text()[-3000:]
    acknowledge(daemon)
    r = daemon.ctl("reset")
    assert r.returncode == 0, (r.stderr, daemon.log.read_text()[-3000:])
    daemon.wait(lambda s: not s["faulted"] and not s.get("resource_status"))
    run_to_success(daemon)


def test_a_killed_controller_is_comm_lost_at_once_and_reset_reconnects_to_the_restarted_one(
    sim: UrSimProcess, daemon: Daemon
) -> None:
    start_mission_until_reach(daemon)
    killed_s = time.monotonic()
    sim.proc.kill()  # its UrSimProcess keeps UR's ports (the machine-wide lock) for this test
    sim.proc.wait()
    s = daemon.wait(lambda s: s["faulted"] and "comm_lost" in s.get("resource_status", []), timeout_s=10)
    # ur_rtde's clients see the socket close; its I/O client may abort the link process first
    words = str(s["fault"])
    assert "the RTDE connection is closed" in words or "the UR link process ended" in words, words
    assert t3_inputs(daemon) == ["T3.CommLost"], daemon.log.read_text()[-3000:]
    ticks = from_telemetry(telemetry(daemon))
    lost = int(np.argmax((ticks.status.astype(int) & Status.COMM_LOST) != 0))
    period_s = 0.002
    # orders of magnitude only on this VM (the figure: a tick or two, the time ur_rtde's
    # thread takes to see the socket close)
    assert ticks.t_s[lost] - killed_s < 50 * period_s, (ticks.t_s[lost] - killed_s) / period_s
    assert not ticks.wrote[lost:].any()  # nothing sent to a controller that is not there
    assert_safe_stop_in_time(ticks, status_shows(ticks, Status.COMM_LOST))
    # no controller to confirm the stop: after safe_stop.timeout_s, the controller's watchdog
    # has stopped its script (or it is off): the stop is done
    daemon.wait(lambda s: "stopped" in s.get("resource_status", []), timeout_s=10)
    acknowledge(daemon)
    r = daemon.ctl("reset")  # the controller is still down
    assert r.returncode != 0 and "cannot reach the dashboard server" in r.stderr, r.stderr
    with UrSimProcess(UR, *SIM_ARGS, lock=False) as restarted:  # the killed one's lock still held
        r = daemon.ctl("reset")
        assert r.returncode == 0, "\n".join(
            (r.stderr, tick_gaps(daemon), restarted.log_text()[-3000:], daemon.log.read_text()[-3000:])
        )
        daemon.wait(lambda s: not s["faulted"] and not s.get("resource_status"))
        run_to_success(daemon)
        daemon.stop()  # ur_rtde's clients go before this simulator does


def run_started(d: Daemon, sim: UrSimProcess, mission: Path) -> list[str]:
    """`mission` loaded and run to success (the simulator's log in a failure); the tasks it
    started, in order."""
    r = d.ctl("load", str(mission))
    assert r.returncode == 0, r.stderr
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running" or s["faulted"], timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], (s.get("fault"), sim.log_text()[-3000:])
    events = d.call("events", last=200)["events"]  # type: ignore[index]
    return [a for e in events if e["kind"] == "instant" for a in e["actions"] if a.startswith("start ")]


def test_computed_torque_motions_run_on_the_controllers_direct_torque(
    sim: UrSimProcess, tmp_path: Path
) -> None:
    """demo_position.mission's three motions with the computed-torque task (Ruckig + computed
    torque: a torque task, move_joints.toml) instead of the position one, through orccadd/orccadctl
    on the UR controller simulator (PolyScope 5.26: direct torque), to success, with the same
    reactive trace as the position mission's on this controller."""
    text = Path(MISSION).read_text().replace("move_joints_csp.toml", "move_joints.toml")
    (tmp_path / "ct_motions.mission").write_text(text.replace('"../tasks/', f'"{ROOT}/configs/tasks/'))
    config = local_config(tmp_path, UR)
    config.write_text(config.read_text().replace("mission_dirs = [", f'mission_dirs = ["{tmp_path}", ', 1))
    d = start_daemon_with(tmp_path, config)
    try:
        started = run_started(d, sim, tmp_path / "ct_motions.mission")
        assert started == ["start Home", "start Reach", "start Back"], started
        assert sim.status()["safety_mode"] == "NORMAL" and sim.status()["protective_stops"] == 0
    finally:
        d.stop()


def test_the_computed_torque_demo_runs_on_the_controllers_direct_torque(
    sim: UrSimProcess, daemon: Daemon
) -> None:
    """demo.mission (Ruckig + computed torque) through orccadd/orccadctl on the UR controller
    simulator, to success. Its Inspect loses tracking mid-motion and Approach waits for ArmSlow:
    meanwhile the arm is held in torque (it ran out of its range, protective stop, in 2 runs of 3
    while the waiting task kept Inspect's last torque)."""
    started = run_started(daemon, sim, ROOT / "configs/missions/demo.mission")
    assert started[:3] == ["start Home", "start Reach", "start Inspect"], started
    assert sim.status()["protective_stops"] == 0


TOOL_OUT_0 = 1 << 16  # RTDE's digital output bits: the tool's outputs at 16-17


def test_a_digital_input_moves_the_mission_and_its_emits_set_the_tools_output(
    sim: UrSimProcess, tmp_path: Path
) -> None:
    """configs/missions/part_io.mission through orccadd on the simulated controller: it waits
    for the part sensor (DI0, raised through the simulator's control channel), closes the
    gripper (TO0 on, seen in the controller's output bits), carries, opens (TO0 off), goes home.
    `send` cannot fake the sensor."""
    d = start_daemon_with(tmp_path, local_config(tmp_path, UR))  # it names DI0 and TO0
    try:
        desc = d.call("describe")
        res = desc["resource"]  # type: ignore[index]
        assert res["inputs"] == ["part_present"] and res["outputs"] == ["close_gripper", "open_gripper"], res
        r = d.ctl("load", str(ROOT / "configs/missions/part_io.mission"))
        assert r.returncode == 0, r.stderr
        d.call("start")
        s = d.wait(lambda s: s["state"] != "ready", timeout_s=10)
        assert s["state"] == "running" and s["active_task"].startswith("Hold"), s  # waiting for the part
        r = d.ctl("send", "arm.part_present")
        assert r.returncode != 0 and "comes from the device" in r.stderr, r.stderr
        assert not sim.status()["digital_output_bits"] & TOOL_OUT_0
        sim.inject("digital_input", index=0, value=True)
        d.wait(lambda s: s["active_task"] == "Carry", timeout_s=10)
        # the outputs go on the arm's output thread, in order, as the automaton emits them
        sim.wait_for(lambda st: bool(st["digital_output_bits"] & TOOL_OUT_0))  # closed as the carry starts
        s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
        assert s["result"] == "success", s
        sim.wait_for(lambda st: not st["digital_output_bits"] & TOOL_OUT_0)  # opened after the carry
        events = d.call("events", last=40)["events"]  # type: ignore[index]
        instants = [e for e in events if e["kind"] == "instant"]
        assert any("arm.part_present" in e["inputs"] for e in instants), instants
        assert any("arm.close_gripper" in " ".join(e["actions"]) for e in instants), instants
    finally:
        d.stop()


SLIDER_MISSION = """
mission Slider
resource arm
input Go
task Out on arm from "{tasks}/ur_move_joints.toml"
  set traj.target_rad = [0.6, -1.3, 1.4, -1.6, -1.5708, 0.3]
  post
end
task Back on arm from "{tasks}/ur_move_joints.toml"
  set traj.target_rad = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
  post
end
main procedure OutAndBack
  handle
    Out; await Go; Back
  on fatal do
    safe
  end
end
safe procedure Rest
  nothing
end
"""


def task_seconds(events: list[dict[str, object]], task: str) -> float:
    """From the instant that started `task` to the one its postcondition ended (trace times)."""
    start = next(float(e["t_s"]) for e in events if f"start {task}" in e.get("actions", []))  # type: ignore[arg-type,operator]
    done = next(float(e["t_s"]) for e in events if f"{task}.done" in e.get("inputs", []))  # type: ignore[arg-type,operator]
    return done - start


def test_the_pendants_speed_slider_slows_a_scaled_motion_through_the_daemon(
    sim: UrSimProcess, tmp_path: Path
) -> None:
    """ur_move_joints.toml (Ruckig scaled by the controller's `speed_scaling`) through orccadd on
    the simulated controller: Out at the slider's 100 %, then the slider set to 50 % on the
    pendant (the simulator's control channel), and Back over the same path takes about twice as
    long; the controller's own scaling, read from RTDE each tick, is what slows it."""
    (tmp_path / "slider.mission").write_text(SLIDER_MISSION.format(tasks=ROOT / "configs/tasks"))
    config = local_config(tmp_path, UR)
    config.write_text(config.read_text().replace("mission_dirs = [", f'mission_dirs = ["{tmp_path}", ', 1))
    d = start_daemon_with(tmp_path, config)
    try:
        assert d.ctl("load", str(tmp_path / "slider.mission")).returncode == 0
        d.call("start")
        deadline = time.monotonic() + 60
        while not any("Out.done" in e.get("inputs", []) for e in d.call("events", last=50)["events"]):  # type: ignore[index]
            assert time.monotonic() < deadline, d.status()
            time.sleep(0.05)  # Out at the slider's 100 %, to its end: the mission waits for Go
        sim.inject("speed_slider", fraction=0.5)
        deadline = time.monotonic() + 10
        while True:  # the controller's scaling follows its slider within a few cycles
            details = d.call("describe")["resource"]["diagnostics"]["details"]  # type: ignore[index]
            if details["speed_slider"] == 0.5 and details["speed_scaling"] == 0.5:
                break
            assert time.monotonic() < deadline, details
            time.sleep(0.05)
        d.call("send", input="Go")
        s = d.wait(lambda s: s["state"] != "running" or s["faulted"], timeout_s=90)
        assert s["result"] == "success" and not s["faulted"], (s.get("fault"), sim.log_text()[-3000:])
        events = d.call("events", last=200)["events"]  # type: ignore[index]
        out, back = task_seconds(events, "Out"), task_seconds(events, "Back")
        assert back / out > 1.5, (out, back)
    finally:
        d.stop()
