"""Several resources in one daemon (configs/robots/dual-arm-sim.toml: two simulated UR5e, `left`
at 1 kHz and `right` at 500 Hz, each in a plant process of its own): a mission's tasks on both at
once, each on its own control thread; a fault on one resource holds the other."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest
from mcap.reader import make_reader

from orccadd.offline.plot import read_log
from tests.daemon.conftest import ROOT, Daemon, start_daemon_with, station_copy

DUAL = ROOT / "configs/robots/dual-arm-sim.toml"
MISSION = str(ROOT / "configs/missions/dual_reach.mission")
pytestmark = pytest.mark.timeout(240, method="thread")


@pytest.fixture(params=["threads", "processes"])
def units(request: pytest.FixtureRequest) -> str:
    """Where each resource's control loop runs (`[daemon] units`): the station's tests hold for both."""
    return str(request.param)


@pytest.fixture
def dual(tmp_path: Path, units: str) -> Iterator[Daemon]:
    dirs = f'mission_dirs = ["{ROOT / "configs/missions"}"]\ntask_dirs = ["{ROOT / "configs/tasks"}"]'
    d = start_daemon_with(tmp_path, station_copy(DUAL, tmp_path, f'units = "{units}"\n{dirs}'))
    try:
        yield d
    finally:
        d.stop()


@pytest.fixture
def slow(tmp_path: Path, units: str) -> Iterator[tuple[Daemon, str]]:
    """The dual arm with missions from `tmp_path` too, and dual_reach there with a slow MeetL
    (seconds: a fault injected while it runs lands in it)."""
    station = station_copy(
        DUAL,
        tmp_path,
        f'units = "{units}"\nmission_dirs = ["{tmp_path}"]\ntask_dirs = ["{ROOT / "configs/tasks"}"]',
    )
    text = Path(MISSION).read_text().replace('"../tasks/', f'"{ROOT}/configs/tasks/')
    head, meet, tail = text.partition("task MeetL")
    meet = meet.replace("  post\n", "  set traj.speed_scale = 0.05\n  post\n", 1)
    (tmp_path / "slow.mission").write_text(head + meet + tail)
    d = start_daemon_with(tmp_path, station)
    try:
        yield d, str(tmp_path / "slow.mission")
    finally:
        d.stop()


def instants(d: Daemon) -> list[dict[str, Any]]:
    events = cast(list[dict[str, Any]], d.call("events", last=200)["events"])  # type: ignore[index]
    return [e for e in events if e["kind"] == "instant"]


def at_rest(status: dict[str, Any], resource: str) -> bool:
    """`resource`'s safe stop is over: it is at rest (`stopped` in its status flags)."""
    unit = next(r for r in status["resources"] if r["name"] == resource)
    return "stopped" in (unit.get("resource_status") or [])


def reaching_left(d: Daemon, mission: str) -> None:
    """`mission` loaded and started, until left runs MeetL (the slow reach: a fault lands in it)."""
    d.call("load", path=mission)
    d.call("start")
    d.wait(lambda s: "MeetL" in str(resources(d)["left"]["task"]), timeout_s=60)


def ticks(d: Daemon, name: str) -> int:
    """The ticks resource `name`'s control loop has run so far."""
    return next(int(u["ticks"]) for u in d.status()["resources"] if u["name"] == name)


def resources(d: Daemon) -> dict[str, dict[str, Any]]:
    described = cast(dict[str, Any], d.call("describe"))
    return {r["name"]: r for r in described["resources"]}


def test_describe_lists_each_resource_with_its_clock_and_hold_task(dual: Daemon) -> None:
    r = resources(dual)
    assert list(r) == ["left", "right"]
    assert (r["left"]["period_s"], r["right"]["period_s"]) == (0.001, 0.002)
    assert r["left"]["clock"] == "loop" and r["left"]["backend"] == "sim_process"
    assert (r["left"]["task"], r["right"]["task"]) == ("Hold_left", "Hold_right")
    assert len(r["left"]["joints"]) == 6 and r["left"]["telemetry"] != r["right"]["telemetry"]


def test_tasks_on_two_resources_run_at_once_and_in_turn(dual: Daemon) -> None:
    dual.call("load", path=MISSION)
    dual.call("start")
    s = dual.wait(lambda s: s["state"] != "running", timeout_s=120)
    assert s["result"] == "success" and not s["faulted"], s
    steps = [(sorted(e["inputs"]), e["actions"]) for e in instants(dual)]
    first = steps[0][1]
    assert "start HomeL" in first and "start HomeR" in first, steps  # both at once
    inputs = [i for ins, _ in steps for i in ins]
    # MeetR starts only on MeetL's postcondition: the order of the postconditions says so
    assert inputs.index("MeetL.done") < inputs.index("MeetR.done"), inputs
    assert inputs.count("HomeL.done") == 2 and inputs.count("HomeR.done") == 2, inputs


def test_a_fault_on_a_moving_resource_enters_the_safe_procedure_and_holds_the_other(
    slow: tuple[Daemon, str],
) -> None:
    dual, mission = slow
    reaching_left(dual, mission)
    dual.call("inject", fault="resource", resource="left")  # left reaches, right holds
    dual.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(dual)), timeout_s=30)
    r = resources(dual)
    assert r["left"]["fault"] and r["left"]["fault"]["resource"] == "left", r["left"]
    assert r["right"]["fault"] is None and r["right"]["task"] == "Hold_right", r["right"]
    dual.call("send", input="Stop")  # its acknowledgement
    # the run ended, and the stopped arm at rest: what `reset` needs (it refused once, in a
    # fresh-clone run: "the safe stop of left is still under way")
    dual.wait(lambda s: s["state"] != "running" and at_rest(s, "left"), timeout_s=30)
    assert cast(dict[str, Any], dual.call("reset"))["reset"]
    assert all(x["fault"] is None for x in resources(dual).values())


def test_a_fault_on_a_held_resource_enters_the_safe_procedure_and_a_reset_names_it(
    slow: tuple[Daemon, str],
) -> None:
    dual, mission = slow
    reaching_left(dual, mission)
    dual.call("inject", fault="resource", resource="right")  # right holds while left reaches
    dual.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(dual)), timeout_s=30)
    entry = next(e for e in instants(dual) if "safe" in e["actions"])
    assert entry["inputs"] == ["right.fault"] and "stop MeetL" in entry["actions"], entry
    assert entry["input_kinds"] == ["t3"], entry  # the resource's type 3, as `top` and the logs tell it
    r = resources(dual)
    assert r["right"]["fault"] and r["right"]["fault"]["resource"] == "right", r["right"]
    assert r["left"]["fault"] is None and r["left"]["task"] == "Hold_left", r["left"]  # held, not stopped
    assert dual.call("status")["state"] == "running"  # the safe procedure awaits Stop
    dual.call("send", input="Stop")  # its acknowledgement
    s = dual.wait(lambda s: s["state"] != "running" and at_rest(s, "right"), timeout_s=30)
    assert s["result"] == "safe", s
    refused = dual.reply("start")
    assert not refused["ok"] and "resource right was safe-stopped" in refused["error"], refused
    assert cast(dict[str, Any], dual.call("reset", resource="right"))["reset"]
    r = resources(dual)
    assert r["right"]["fault"] is None and r["right"]["task"] == "Hold_right"


def test_one_arms_plant_killed_while_it_moves_stops_it_alone(slow: tuple[Daemon, str]) -> None:
    dual, mission = slow
    reaching_left(dual, mission)
    os.kill(resources(dual)["left"]["helper_pid"], signal.SIGKILL)  # its "controller" gone
    dual.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(dual)), timeout_s=30)
    r = resources(dual)
    assert r["left"]["fault"]["kind"] == "comm_lost" and r["left"]["fault"]["resource"] == "left", r["left"]
    assert r["right"]["fault"] is None and r["right"]["task"] == "Hold_right", r["right"]
    dual.call("send", input="Stop")
    dual.wait(lambda s: s["state"] != "running" and at_rest(s, "left"), timeout_s=30)
    assert cast(dict[str, Any], dual.call("reset", resource="left"))["reset"]  # a new plant
    assert resources(dual)["left"]["fault"] is None


def test_a_mission_on_a_resource_the_cell_lacks_is_refused_at_its_line(dual: Daemon) -> None:
    refused = dual.reply("load", path=str(ROOT / "configs/missions/grasp.mission"))
    assert not refused["ok"], refused
    assert "task Open runs on `gripper`, but this robot's resources are `left`, `right`" in refused["error"]
    assert dual.status()["state"] == "idle"  # nothing loaded, nothing moved


def test_a_resource_that_fails_at_startup_stops_the_daemon_naming_it(tmp_path: Path) -> None:
    # the two arms start (their plants), then the left hand's chain is not there: exit 2 naming
    # it, no socket served
    station = station_copy(ROOT / "configs/robots/dual-arm-grippers-sim.toml", tmp_path)
    station.write_text(station.read_text().replace("/tmp/orccadd-left-hand", str(tmp_path / "no-such-chain")))
    cmd = [
        sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(station),
        "--socket", str(tmp_path / "run/orccadd.sock"),
    ]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "resource left_hand: " in out.stderr and "no-such-chain" in out.stderr, out.stderr
    assert not (tmp_path / "run/orccadd.sock").exists()


def test_orccadctl_describes_and_shows_each_resource_in_words(dual: Daemon) -> None:
    def ctl(*args: str) -> str:
        env = {**os.environ, "ORCCADD_SOCKET": str(dual.socket)}
        out = subprocess.run(
            [sys.executable, "-m", "orccadd.cli", *args], capture_output=True, text=True, timeout=60, env=env
        )
        assert out.returncode == 0, out.stderr
        return out.stdout

    text = ctl("describe")
    assert "robot dual-arm-sim: 2 resources, each on its own control thread" in text, text
    assert "left: 6 joints, period 1 ms (1000 Hz), clock loop, task Hold_left" in text, text
    assert "right: 6 joints, period 2 ms (500 Hz), clock loop, task Hold_right" in text, text
    status = ctl("status")
    assert "left: task Hold_left (run), resource ok" in status and "right: task Hold_right" in status
    assert status.count("  loop: ") == 2, status
    dual.call("load", path=MISSION)
    mission = cast(dict[str, Any], dual.call("describe"))["mission"]
    text = ctl("describe")
    for task, res in zip(mission["tasks"], mission["task_resources"], strict=True):
        assert f"{task} (on {res})" in text, text  # each task with the resource it runs on
    assert set(mission["task_resources"]) == {"left", "right"}


def test_a_reset_or_an_injection_naming_no_resource_is_refused_and_nothing_changes(dual: Daemon) -> None:
    for cmd, args in (
        ("reset", {"resource": "middle"}),
        ("inject", {"fault": "resource", "resource": "middle"}),
    ):
        r = dual.reply(cmd, **args)
        assert not r["ok"] and "no resource 'middle' (resources: left, right)" in r["error"], r
    s = dual.status()
    assert not s["faulted"] and s["state"] == "idle", s
    assert all(x["fault"] is None for x in resources(dual).values())


def test_a_log_of_the_cell_has_each_resource_at_its_rate_and_one_mcap(dual: Daemon, tmp_path: Path) -> None:
    """`orccadctl log` through a real daemon while both arms move: a CSV per resource, rows at its
    own period, the mission's instants in each; one MCAP (every joint of both arms on
    `/joint_states`, named by resource: the two arms share their joint names); `log stop -o`
    copies them all; `monitor` samples both, each label named by its resource."""
    with dual.client() as c:
        head, *samples = c.stream("monitor", signals=["q.0", "right/tau.0"], rate_hz=50, count=2)
    labels = head["signals"]
    assert len(samples) == 2 and all(len(s["values"]) == 3 for s in samples), samples
    assert labels == [
        "t_s",
        "left/q.shoulder_pan_joint",
        "right/q.shoulder_pan_joint",
        "right/tau.shoulder_pan_joint",
    ]
    out = dual.ctl("log", "start", "q", "wake_us", "--name", "reach.csv")
    assert out.returncode == 0 and "reach.left.csv" in out.stdout and "reach.right.csv" in out.stdout, out
    dual.call("load", path=MISSION)
    dual.call("start")
    dual.wait(lambda s: s["state"] != "running", timeout_s=120)
    out = dual.ctl("log", "stop", "-o", str(tmp_path / "copy.csv"))
    assert out.returncode == 0, out.stderr
    for name in ("copy.left.csv", "copy.right.csv", "copy.mcap"):
        assert (tmp_path / name).stat().st_size > 0, out.stdout
    left, right = read_log(tmp_path / "copy.left.csv"), read_log(tmp_path / "copy.right.csv")
    assert left.columns[1] == "left/q.shoulder_pan_joint" and right.columns[-1] == "right/wake_us"
    # each resource at its own period (a skipped tick is a longer step, never a shorter one)
    assert abs(float(np.median(np.diff(left.data[:, 0]))) - 0.001) < 1e-6
    assert abs(float(np.median(np.diff(right.data[:, 0]))) - 0.002) < 1e-6
    for d in (left, right):
        assert any(kind == "instant" for _, kind, _ in d.events)  # the mission's instants in both
    with (tmp_path / "copy.mcap").open("rb") as fh:
        names = set()
        topics = set()
        for _, ch, m in make_reader(fh).iter_messages():
            topics.add(ch.topic)
            if ch.topic == "/joint_states":
                names |= {j["name"] for j in json.loads(m.data)["joints"]}
    assert {"/left/q", "/right/q", "/left/wake_us", "/right/wake_us", "/events"} <= topics
    assert len(names) == 12 and "left/elbow_joint" in names and "right/elbow_joint" in names


def test_a_mission_compiled_as_a_network_runs_each_branch_on_its_arm(tmp_path: Path) -> None:
    """relay_network.mission: a `par` of two independent branches (thirty dwells on each arm)
    compiles as a network; `load` checks it on its products, as `orccadctl check` does, and the
    daemon steps it with the network runner: both branches at once, each arm through its
    thirty tasks in order, the run a success."""
    missions = ROOT / "tests/daemon/missions"
    station = station_copy(
        DUAL, tmp_path, f'mission_dirs = ["{missions}"]\ntask_dirs = ["{ROOT / "configs/tasks"}"]'
    )
    d = start_daemon_with(tmp_path, station)
    try:
        d.call("load", path=str(missions / "relay_network.mission"))
        mission = cast(dict[str, Any], d.call("describe"))["mission"]
        assert mission["network"] and "branches of the par at line" in mission["network"], mission
        d.call("start")
        s = d.wait(lambda s: s["state"] != "running", timeout_s=120)
        assert s["result"] == "success" and not s["faulted"], s
        steps = [(e["inputs"], e["actions"]) for e in instants(d)]
        # a fault on one arm mid-run: the context kills both branches, enters the safe procedure
        d.call("start")
        d.wait(lambda s: "DwellL" in str(resources(d)["left"]["task"]), timeout_s=60)
        d.call("inject", fault="resource", resource="left")
        d.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(d)), timeout_s=30)
        r = resources(d)
        assert r["right"]["task"] == "Hold_right" and r["left"]["fault"]["resource"] == "left", r
        d.call("send", input="Stop")
        s = d.wait(lambda s: s["state"] != "running", timeout_s=30)
        assert s["result"] == "safe", s
    finally:
        d.stop()
    assert "start DwellL0" in steps[0][1] and "start DwellR0" in steps[0][1], steps[0]
    for side in "LR":  # each branch through its thirty dwells, alternating its two tasks
        done = [i for ins, _ in steps for i in ins if i.startswith(f"Dwell{side}")]
        assert done == [f"Dwell{side}{k % 2}.done" for k in range(30)], done


def test_a_control_thread_that_fails_faults_its_resource_alone_and_a_reset_starts_it_again(
    slow: tuple[Daemon, str],
) -> None:
    # a bug in left's control thread (injected: its next tick raises) while left reaches: left
    # safe-stopped with an `internal` fault, the mission's safe procedure entered on left.fault,
    # right holding and ticking all along; the daemon runs on, and `reset` restarts the thread
    dual, mission = slow
    reaching_left(dual, mission)
    dual.call("inject", fault="control_thread", resource="left")
    dual.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(dual)), timeout_s=30)
    entry = next(e for e in instants(dual) if "safe" in e["actions"])
    assert entry["inputs"] == ["MeetL.T3.LawError"], entry  # the task it ran: its type 3
    r = resources(dual)
    fault = r["left"]["fault"]
    assert (
        fault["kind"] == "internal" and fault["resource"] == "left" and fault["event"] == "MeetL.T3.LawError"
    ), fault
    assert "injected failure of the control thread" in fault["text"], fault
    assert r["right"]["fault"] is None and r["right"]["task"] == "Hold_right", r["right"]

    left, right = ticks(dual, "left"), ticks(dual, "right")
    dual.wait(lambda s: ticks(dual, "right") > right + 100, timeout_s=10)  # right ticks on (500 Hz)
    assert ticks(dual, "left") == left  # left's thread has ended
    dual.call("send", input="Stop")
    dual.wait(lambda s: s["state"] != "running", timeout_s=30)
    assert cast(dict[str, Any], dual.call("reset", resource="left"))["reset"]
    r = resources(dual)
    assert r["left"]["fault"] is None and r["left"]["task"] == "Hold_left", r["left"]
    dual.wait(lambda s: ticks(dual, "left") > left + 100, timeout_s=10)  # its control thread again
    dual.call("start")  # and left moves again: the mission's tasks on it
    dual.wait(lambda s: "MeetL" in str(resources(dual)["left"]["task"]), timeout_s=60)
    dual.call("send", input="Stop")
    s = dual.wait(lambda s: s["state"] != "running", timeout_s=30)
    assert not s["faulted"], s


def test_a_control_thread_that_hangs_in_a_device_call_faults_its_resource_alone(
    slow: tuple[Daemon, str],
) -> None:
    # left's next tick waits 5 s (injected: a read that does not return) while left reaches:
    # within its watchdog (50 periods, at least 0.25 s) left is faulted comm_lost naming where
    # its thread waits, the mission's safe procedure entered on MeetL's CommLost, right ticking
    # all along; once the call returns left's loop ticks again, safe-stopped, and a reset clears it
    dual, mission = slow
    reaching_left(dual, mission)

    dual.call("inject", fault="hang", extra_ms=5000.0, resource="left")
    dual.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(dual)), timeout_s=10)
    entry = next(e for e in instants(dual) if "safe" in e["actions"])
    assert entry["inputs"] == ["MeetL.T3.CommLost"], entry
    fault = resources(dual)["left"]["fault"]
    assert fault["kind"] == "comm_lost" and fault["resource"] == "left", fault
    assert "has not ticked for" in fault["text"] and "loop.py" in fault["text"], fault  # where it waits
    left, right = ticks(dual, "left"), ticks(dual, "right")
    dual.call("send", input="Stop")  # the safe procedure's acknowledgement: the run ends
    dual.wait(lambda s: s["state"] != "running", timeout_s=10)
    refused = dual.reply("reset", resource="left")
    assert not refused["ok"] and "still does not tick" in refused["error"], refused  # the call hangs
    dual.wait(lambda s: ticks(dual, "right") > right + 100, timeout_s=10)  # right ticks on meanwhile
    assert resources(dual)["right"]["fault"] is None
    dual.wait(lambda s: ticks(dual, "left") > left + 100 and at_rest(s, "left"), timeout_s=20)  # it returned
    assert cast(dict[str, Any], dual.call("reset", resource="left"))["reset"]
    r = resources(dual)
    assert r["left"]["fault"] is None and r["left"]["task"] == "Hold_left", r["left"]


@pytest.mark.parametrize("units", ["processes"])
def test_a_unit_process_that_dies_faults_its_resource_alone_and_a_reset_starts_a_new_one(
    slow: tuple[Daemon, str],
) -> None:
    # left's unit process dies at once (injected: as a driver's segfault would end it) while left
    # reaches: left faulted `internal` naming its process's end, the mission's safe procedure
    # entered on MeetL's LawError, right ticking all along; `reset` starts a new unit process,
    # which holds left and builds the mission's tasks again: the mission runs on left again
    dual, mission = slow
    reaching_left(dual, mission)
    pid = next(u["unit_pid"] for u in dual.call("describe")["resources"] if u["name"] == "left")
    dual.call("inject", fault="unit_process", resource="left")
    dual.wait(lambda s: s["faulted"] and any("safe" in e["actions"] for e in instants(dual)), timeout_s=30)
    entry = next(e for e in instants(dual) if "safe" in e["actions"])
    assert entry["inputs"] == ["MeetL.T3.LawError"], entry
    fault = resources(dual)["left"]["fault"]
    assert fault["kind"] == "internal" and "process ended" in fault["text"], fault
    right = ticks(dual, "right")
    dual.wait(lambda s: ticks(dual, "right") > right + 100, timeout_s=10)  # right ticks on
    assert resources(dual)["right"]["fault"] is None
    dual.call("send", input="Stop")
    dual.wait(lambda s: s["state"] != "running", timeout_s=30)
    left = ticks(dual, "left")
    assert cast(dict[str, Any], dual.call("reset", resource="left"))["reset"]
    r = next(u for u in dual.call("describe")["resources"] if u["name"] == "left")
    assert r["unit_pid"] != pid and r["fault"] is None and r["task"] == "Hold_left", r
    dual.wait(lambda s: ticks(dual, "left") > left + 100, timeout_s=10)  # counted on, not from 0
    dual.call("start")  # the mission's tasks, built again in the new process
    dual.wait(lambda s: "MeetL" in str(resources(dual)["left"]["task"]), timeout_s=60)
    dual.call("send", input="Stop")
    s = dual.wait(lambda s: s["state"] != "running", timeout_s=30)
    assert not s["faulted"], s
