"""orccadctl's side of `move`, `jog` and `follow` (no daemon: a stand-in connection): what it
refuses before sending, the wait for the run's end, Ctrl-C while waiting (a `stop`), the words.
The commands against a daemon: tests/daemon/test_move.py."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from orccadd.cli import build_parser
from orccadd.ctl import motion
from orccadd.ctl.client import ClientError
from orccadd.wire.commands import MAX_LINE
from tests.ctl.test_human import run

JOINTS = ("a", "b")


def parse(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(motion.joined_values(list(argv)))


def test_a_negative_first_value_is_taken_as_the_joints_value() -> None:
    assert parse("move", "--joints", "-0.5,1").joints == "-0.5,1"
    assert parse("move", "--joints=-0.5,1", "--speed-scale", "0.2").speed_scale == 0.2
    assert parse("jog", "--joint", "a", "--by", "-0.1").by == -0.1
    assert motion.request(parse("move", "--joints", "-0.5,1e-3")) == (
        "move",
        {"joints_rad": [-0.5, 0.001], "speed_scale": 0.5},
    )
    cmd, args = motion.request(parse("jog", "--joint", "a", "--by", "0.2", "--resource", "left"))
    assert (cmd, args) == ("jog", {"joint": "a", "by_rad": 0.2, "speed_scale": 0.5, "resource": "left"})


def test_what_is_not_numbers_or_not_a_readable_file_is_refused_before_sending(tmp_path: Path) -> None:
    with pytest.raises(ClientError, match=r"move: --joints '1,x': want numbers separated by commas"):
        motion.request(parse("move", "--joints", "1,x"))
    r = run("move", "--joints", "1,x", "--socket", "/nonexistent.sock")
    assert r.code == 2 and "want numbers separated by commas" in r.err
    r = run("follow", str(tmp_path / "none.csv"), "--socket", "/nonexistent.sock")
    assert r.code == 2 and "none.csv: No such file or directory" in r.err


def test_a_trajectory_too_large_for_one_request_is_refused_saying_how_many_points_fit(tmp_path: Path) -> None:
    path = tmp_path / "dense.csv"
    rows = [f"{k * 0.001:.3f},{0.1 + k * 1e-6:.6f},{0.2 - k * 1e-6:.6f}" for k in range(5000)]
    path.write_text("t_s,a,b\n" + "\n".join(rows) + "\n")
    with pytest.raises(ClientError) as e:
        motion.request(parse("follow", str(path)))
    why = str(e.value)
    assert (
        why.startswith(f"follow: {path}: 5000 points make a request of ")
        and f"the protocol's {MAX_LINE}" in why
    )
    fit = int(why.split("at most about ")[1].split()[0])
    assert 1000 < fit < 5000  # and so many do fit:
    small = tmp_path / "small.csv"
    small.write_text("t_s,a,b\n" + "\n".join(rows[: fit - 10]) + "\n")
    cmd, args = motion.request(parse("follow", str(small), "--resource", "arm"))
    assert cmd == "follow" and args["name"] == "small.csv" and args["resource"] == "arm"


class StandIn:
    """A connection whose `status` replies are given in advance; it records what it is asked."""

    def __init__(self, states: list[dict[str, Any]]) -> None:
        self.states = states
        self.asked: list[str] = []

    def __enter__(self) -> StandIn:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def call(self, cmd: str, **args: Any) -> Any:
        self.asked.append(cmd)
        return self.states.pop(0)

    def reply(self, cmd: str, **args: Any) -> dict[str, Any]:
        self.asked.append(cmd)
        if cmd == "status":
            return {"ok": True, "result": self.states.pop(0)}
        if cmd == "stop":
            return {"ok": True, "result": {"stopped": True}}
        started = {"resource": "arm", "mode": "torque", "task_file": "/x/move_joints.toml"}
        return {"ok": True, "result": {**started, "target_rad": [0.1, 0.2]}}


def test_it_waits_for_the_run_to_end_and_says_how(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(motion, "POLL_S", 0.0)
    running = {"state": "running", "result": "none", "fault": None, "joints": []}
    ok = {**running, "state": "ready", "result": "success"}
    conn = StandIn([running, running, ok])
    monkeypatch.setattr(motion, "Client", lambda *a, **k: conn)
    r = run("move", "--joints", "0.1,0.2", "--socket", "/x.sock")
    assert r.code == 0 and conn.asked == ["move", "status", "status", "status"]
    assert r.out.splitlines() == [
        "move: started on arm (torque: move_joints.toml), to [0.1, 0.2] rad",
        "arrived (mission ended: success)",
    ]
    fault = {"event": "Move.T3.NearJointLimit", "kind": "limit", "text": "elbow near its limit"}
    conn.states = [running, {**running, "state": "ready", "result": "safe", "fault": fault}]
    r = run("move", "--joints", "0.1,0.2", "--socket", "/x.sock")
    assert r.code == 1
    assert r.out.splitlines()[-1] == (
        "did not arrive: the run ended safe: Move.T3.NearJointLimit: elbow near its limit; "
        "`orccadctl reset` once at rest"
    )
    conn.asked = []
    r = run("move", "--joints", "0.1,0.2", "--no-wait", "--socket", "/x.sock")
    assert r.code == 0 and conn.asked == ["move"]


def test_ctrl_c_while_waiting_stops_the_run(monkeypatch: pytest.MonkeyPatch) -> None:
    class Interrupted(StandIn):
        def call(self, cmd: str, **args: Any) -> Any:
            self.asked.append(cmd)
            raise KeyboardInterrupt

    conn = Interrupted([])
    monkeypatch.setattr(motion, "Client", lambda *a, **k: conn)
    r = run("jog", "--joint", "a", "--by", "0.1", "--socket", "/x.sock")
    assert r.code == 130 and conn.asked == ["jog", "status", "stop"]
    assert r.err == "stopped: the arm is held where it is\n"


def test_a_refusal_is_the_daemons_words_on_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    class Refusing(StandIn):
        def reply(self, cmd: str, **args: Any) -> dict[str, Any]:
            return {"ok": False, "error": "move: 1 values for the 2 joints of arm (a, b)"}

    monkeypatch.setattr(motion, "Client", lambda *a, **k: Refusing([]))
    r = run("move", "--joints", "0.1", "--socket", "/x.sock")
    assert (r.code, r.out) == (1, "")
    assert r.err == "orccadctl: error: move: 1 values for the 2 joints of arm (a, b)\n"
