"""`orccadctl top`: the pure frame renderer (colours, a small terminal, goal and last error) and
the keys, dispatched to the daemon's commands through a stand-in server (no terminal needed:
the key source and the screen are injected)."""

from __future__ import annotations

import json
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from orccadd.ctl.client import Client
from orccadd.ctl.terminal import colour_wanted
from orccadd.ctl.top import KEY_COMMANDS, Top, newest_exception, render
from orccadd.wire.commands import COMMANDS, Role

# Replies of a real orccadd (sim-ur5e, demo.mission: started, held, resumed, a resource fault
# injected), joints cut to two. tests/ctl/test_human.py checks them against a live daemon's.
TIMING = {
    "window_ticks": 414.0, "wake_median_us": 18.3, "wake_p99_us": 241.2, "wake_max_us": 285.8,
    "compute_median_us": 54.2, "compute_p99_us": 93.3, "compute_max_us": 183.1,
}  # fmt: skip
JOINTS = [
    {"name": "shoulder_pan_joint", "q_rad": 0.29891, "dq_rad_s": -0.0761, "tau_nm": -10.561, "cmd": -10.997},
    {"name": "shoulder_lift_joint", "q_rad": -1.20118, "dq_rad_s": -0.0786, "tau_nm": -43.52, "cmd": -43.91},
]
RUNNING: dict[str, Any] = {
    "robot": "ur5e", "state": "running", "mission": "PickDemo", "automaton_state": 1, "instants": 2,
    "result": "none", "faulted": False, "fault": None, "helper_pid": 1210, "ticks": 414, "overruns": 0,
    "switches": 2, "heartbeat_age_s": 0.0005, "timing": TIMING, "log": None, "active_task": "Home",
    "task_phase": "run", "resource_status": [], "joints": JOINTS,
    "rt_link": {"discarded": {}, "late_replies": 0},
}  # fmt: skip
HOLDING = {**RUNNING, "state": "holding", "active_task": "Hold", "switches": 3}
CAUSE = {
    "event": "Home.T3.ResourceFault", "kind": "device", "resource": "arm", "joint": "", "code": 9999,
    "text": "injected fault",
}  # fmt: skip
FAULTED = {
    **RUNNING, "automaton_state": 4, "instants": 4, "faulted": True, "fault": CAUSE, "active_task": "Hold",
    "task_phase": "fault", "resource_status": ["fault", "stopped", "torque_off"],
}  # fmt: skip
EVENTS: list[dict[str, Any]] = [
    {"seq": 5, "kind": "command", "t_s": 33065.930611, "time": "00:59:53.393", "command": "hold"},
    {"seq": 6, "kind": "command", "t_s": 33065.986598, "time": "00:59:53.449", "command": "resume"},
    {"seq": 7, "kind": "instant", "t_s": 33065.988239, "time": "00:59:53.451", "mission": "PickDemo",
     "from": 1, "to": 1, "inputs": ["Home.pre"], "input_kinds": ["pre"], "actions": []},
    {"seq": 8, "kind": "command", "t_s": 33065.990775, "time": "00:59:53.454", "command": "inject"},
    {"seq": 9, "kind": "fault", "t_s": 33065.992100, "time": "00:59:53.455", "fault": {"n": 1, **CAUSE}},
    {"seq": 10, "kind": "instant", "t_s": 33065.992239, "time": "00:59:53.455", "mission": "PickDemo",
     "from": 1, "to": 4, "inputs": ["Home.T3.ResourceFault"], "input_kinds": ["t3"],
     "actions": ["stop Home", "safe"]},
    {"seq": 11, "kind": "event", "t_s": 33065.994239, "time": "00:59:53.457",
     "event": "Hold.T3.ResourceFault", "event_kind": "t3"},
]  # fmt: skip
for _e in EVENTS:  # Unix time, as the daemon gives it beside the clock's words
    _e["wall_s"] = 1795000000.0 + sum(float(x) * 60**i for i, x in enumerate(reversed(_e["time"].split(":"))))
SIZE = (100, 30)


def line(frame: list[str], head: str) -> str:
    return next(x for x in frame if x.startswith(head))


def test_a_frame_without_colours_fits_the_terminal_and_shows_goal_and_events() -> None:
    frame = render(RUNNING, EVENTS[:3], SIZE)
    assert not any("\x1b" in x for x in frame)
    assert all(len(x) <= SIZE[0] for x in frame) and len(frame) <= SIZE[1]
    assert frame[0].startswith("orccadd top: ur5e") and frame[0].endswith("q quit  p pause  h hold  r resume")
    assert line(frame, "state").startswith("state    running, mission PickDemo, automaton state 1")
    assert line(frame, "goal") == "goal     Home (run)"
    assert line(frame, "error") == "error    -"
    assert frame[-1].endswith("instant 1->1  inputs {Home.pre}  actions {-}")  # the newest last


def test_colours_for_states_only_when_asked() -> None:
    def state_line(s: dict[str, Any]) -> str:
        return line(render(s, [], SIZE, colour=True), "state")

    assert "\x1b[32mrunning\x1b[0m," in state_line(RUNNING)
    assert "\x1b[33mholding\x1b[0m," in state_line(HOLDING)
    stopping = {**RUNNING, "resource_status": ["stopping"]}
    assert "\x1b[33mrunning\x1b[0m" in state_line(stopping)
    # a fault while the mission runs: its safe procedure, in red, in the daemon's words
    assert "\x1b[31mrunning (safe procedure), faulted\x1b[0m" in state_line(FAULTED)
    assert "\x1b[" not in state_line({**RUNNING, "state": "ready", "active_task": "Hold"})


def test_colours_need_a_terminal_and_no_no_color_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    class Tty:
        def isatty(self) -> bool:
            return True

    monkeypatch.delenv("NO_COLOR", raising=False)
    assert colour_wanted(Tty())  # type: ignore[arg-type]
    monkeypatch.setenv("NO_COLOR", "1")
    assert not colour_wanted(Tty())  # type: ignore[arg-type]
    monkeypatch.delenv("NO_COLOR")
    with open(__file__) as f:
        assert not colour_wanted(f)  # a file: no terminal


def test_a_terminal_too_small_is_said_so() -> None:
    assert render(RUNNING, EVENTS, (40, 10)) == ["terminal too small: need 66x12"]
    assert render(RUNNING, EVENTS, (20, 40)) == ["terminal too small: "]  # cut to the width
    assert len(render(RUNNING, EVENTS, (66, 12))) == 12  # just enough: one event


def test_the_last_error_is_the_fault_first_then_the_newest_exception() -> None:
    # found by the kinds the records carry, not by their names
    assert newest_exception(EVENTS) == (11, "00:59:53.457 Hold.T3.ResourceFault")
    assert newest_exception(EVENTS[:6]) == (10, "00:59:53.455 Home.T3.ResourceFault")
    assert newest_exception(EVENTS[:5]) == (
        9,
        "00:59:53.455 safe stop: Home.T3.ResourceFault (arm: injected fault)",
    )
    assert newest_exception(EVENTS[:3]) is None
    named_alike = [{**EVENTS[6], "event": "Hold.T3.Like", "event_kind": "t1"}]  # a T1 named like a T3
    assert newest_exception(named_alike) is None
    frame = render(FAULTED, EVENTS, SIZE, colour=True)
    assert line(frame, "error") == (
        "error    \x1b[31mfault: Home.T3.ResourceFault (arm: injected fault) (`reset` needed)\x1b[0m"
    )
    assert line(frame, "goal") == "goal     Hold (fault)"
    assert line(frame, "resource") == "resource \x1b[31mfault, stopped, torque_off\x1b[0m"
    reset = {**RUNNING, "state": "ready", "active_task": "Hold"}  # after `reset`: the fault is gone
    frame = render(reset, EVENTS, SIZE, last_error="00:59:53.457 Hold.T3.ResourceFault")
    assert line(frame, "error") == "error    00:59:53.457 Hold.T3.ResourceFault"
    success = {**RUNNING, "state": "ready", "result": "success"}  # a type 2 the mission handled
    frame = render(success, EVENTS, SIZE, colour=True, last_error="00:59:53.300 Close.T2.Missed")
    assert line(frame, "handled") == "handled  00:59:53.300 Close.T2.Missed"  # no error, not red
    held = render(HOLDING, [], SIZE)
    assert line(held, "goal") == "goal     Hold (run): the mission is suspended (r resumes)"


# ---- keys, against a stand-in server ------------------------------------------------------
@pytest.fixture
def server(tmp_path: Path) -> Iterator[tuple[str, list[str]]]:
    """Answers status, events, hold (ok) and resume (refused, in the daemon's words), many
    requests per connection; records the commands it was sent."""
    path = str(tmp_path / "s.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(path)
    srv.listen()
    seen: list[str] = []
    results = {
        "status": RUNNING,
        "events": {"events": EVENTS[:3], "lost": 0},
        "hold": {"holding": True},
    }

    def serve() -> None:
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn, conn.makefile("rb") as f:
                for raw in f:
                    req = json.loads(raw)
                    seen.append(req["cmd"])
                    if req["cmd"] in results:
                        reply = {"id": req["id"], "ok": True, "result": results[req["cmd"]]}
                    else:
                        error = f"cannot {req['cmd']} while running (only when holding)"
                        reply = {"id": req["id"], "ok": False, "error": error}
                    conn.sendall((json.dumps(reply) + "\n").encode())

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    yield path, seen
    srv.shutdown(socket.SHUT_RDWR)  # wakes the accept()
    srv.close()
    t.join(timeout=5)
    assert not t.is_alive()


class Keys:
    def __init__(self, *keys: str | None) -> None:
        self.keys = list(keys)

    def read(self, timeout_s: float) -> str | None:
        return self.keys.pop(0) if self.keys else "q"


class Screen:
    colour = False

    def __init__(self) -> None:
        self.frames: list[list[str]] = []

    def size(self) -> tuple[int, int]:
        return SIZE

    def draw(self, lines: list[str]) -> None:
        self.frames.append(lines)


def test_the_keys_are_commands_of_the_table() -> None:
    assert KEY_COMMANDS == {"h": "hold", "r": "resume"}
    assert all(COMMANDS[c].role is Role.CONTROL for c in KEY_COMMANDS.values())


def test_keys_send_hold_and_resume_pause_the_display_and_quit(server: tuple[str, list[str]]) -> None:
    path, seen = server
    screen = Screen()
    with Client(path) as c:
        Top(c, Keys(None, "h", "r", "p", None, "x", "q"), screen, rate_hz=1000.0).run()
    # each refresh asks status and events; the keys add their commands; nothing after q
    assert [s for s in seen if s not in ("status", "events")] == ["hold", "resume"]
    assert seen[:2] == ["status", "events"] and seen[-2:] == ["status", "events"]
    notes = [line(f, "> ") if any(x.startswith("> ") for x in f) else "" for f in screen.frames]
    assert notes[0] == notes[1] == ""
    assert notes[2].startswith("> holding: the mission is suspended")
    assert notes[3] == "> resume refused: cannot resume while running (only when holding)"
    assert line(screen.frames[3], "error").endswith(
        " resume: cannot resume while running (only when holding)"
    )  # the refused command is the last error, stamped with its time
    assert notes[4] == "> display paused (p: go on)" and "[paused]" in screen.frames[4][0]
    assert seen.count("status") == 4  # the pause froze the display: no refresh after p
    assert notes[6] == "> keys: q quit  p pause  h hold  r resume"  # an unknown key


def test_count_ends_the_view(server: tuple[str, list[str]]) -> None:
    path, seen = server
    screen = Screen()
    with Client(path) as c:
        Top(c, Keys(), screen, rate_hz=1000.0, count=1).run()
    assert len(screen.frames) == 1 and seen == ["status", "events"]


def test_a_cell_shows_each_resource_its_goal_loop_and_joints() -> None:
    joint = {"name": "j1", "q_rad": 0.1, "dq_rad_s": 0.0, "tau_nm": 0.0, "cmd": 0.0}
    loop = {"ticks": 10, "overruns": 0, "switches": 1, "timing": {}, "joints": [joint]}
    left = {"name": "left", "active_task": "MeetL", "task_phase": "run", "resource_status": [], **loop}
    right = {
        "name": "right",
        "active_task": "Hold_right",
        "task_phase": "run",
        "resource_status": ["stopped"],
    }
    status = {
        "robot": "dual", "state": "running", "result": "none", "automaton_state": 3, "faulted": False,
        "resources": [left, {**right, **loop, "fault": {"kind": "device"}}], **loop,
    }  # fmt: skip
    frame = render(status, [], (100, 30))
    assert "left: MeetL (run)" in frame and "right: Hold_right (run)" in frame, frame
    assert "  resource stopped" in frame and sum("j1" in line for line in frame) == 2, frame
    assert all(len(line) <= 100 for line in frame)
    assert render(status, [], (100, 12)) == ["terminal too small: need 66x17"]
