"""orccadctl's words for people: each online command against a real orccadd (sim-ur5e, the demo
mission), JSON with --json, refusals in one line in the daemon's words, Ctrl-C quiet (exit 130)."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import pytest

from orccadd.cli import build_parser, orccadctl_main
from orccadd.ctl import cell as ctl_cell
from orccadd.ctl import deploy as ctl_deploy
from orccadd.ctl import fetch as ctl_fetch
from orccadd.ctl import foxglove, motion, online
from orccadd.ctl.format import bounds, num
from orccadd.offline import commands as offline
from orccadd.offline import compare_cli, replayrun
from tests.ctl.test_streams import server  # noqa: F401  (the stand-in stream server)
from tests.ctl.test_top import EVENTS, RUNNING
from tests.daemon.conftest import ROOT, start_daemon

DEMO = str(ROOT / "configs/missions/demo.mission")


class Out(NamedTuple):
    code: int
    out: str
    err: str


def run(*argv: str) -> Out:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = orccadctl_main(list(argv))
    return Out(code, out.getvalue(), err.getvalue())


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """One orccadd, driven once through orccadctl as an operator would; every output by name,
    and the daemon's own replies (`raw_*`) to compare the words with."""
    d = start_daemon(tmp_path_factory.mktemp("human"))
    try:
        sock = ("--socket", d.socket)
        o: dict[str, Any] = {"raw_hold_idle": d.reply("hold")}
        o["hold_idle"] = run(*sock, "hold")
        o["describe_idle"] = run(*sock, "describe")
        o["load"] = run(*sock, "load", DEMO)
        o["describe"] = run(*sock, "describe")
        o["describe_json"] = run(*sock, "--json", "describe")
        o["describe_json_after"] = run(*sock, "describe", "--json")
        o["raw_tune_refused"] = d.reply("tune", path="Reach.ct.kp[0]", value=-3)
        o["tune_refused"] = run(*sock, "tune", "Reach.ct.kp[0]", "-3")
        o["tune"] = run(*sock, "tune", "Reach.ct.kp[2]", "500")
        o["start"] = run(*sock, "start")
        o["raw_status"] = d.status()
        o["hold"] = run(*sock, "hold")
        o["resume"] = run(*sock, "resume")
        o["params"] = run(*sock, "params", "Reach")
        o["events"] = run(*sock, "events", "--last", "3")
        o["raw_events"] = d.call("events", last=20)
        o["top"] = run(*sock, "top", "--count", "1")
        o["top_json"] = run(*sock, "--json", "top", "--count", "1")
        o["stop"] = run(*sock, "stop")
        o["reset"] = run(*sock, "reset")
        o["log_start"] = run(*sock, "log", "start", "q")
        o["log_stop"] = run(*sock, "log", "stop")
        o["abort"] = run(*sock, "abort")
        o["status"] = run(*sock, "status")
        yield o
    finally:
        d.stop()


def test_the_samples_of_the_pure_tests_have_the_real_shapes(session: dict[str, Any]) -> None:
    assert set(session["raw_status"]) == set(RUNNING)
    assert set(session["raw_status"]["joints"][0]) == set(RUNNING["joints"][0])
    sample = {e["kind"]: set(e) for e in EVENTS}
    real = {e["kind"]: set(e) for e in session["raw_events"]["events"]}
    assert set(real) == {"command", "instant"} and all(real[k] == sample[k] for k in real)


def test_a_refusal_is_one_line_in_the_daemons_words(session: dict[str, Any]) -> None:
    for name in ("hold_idle", "tune_refused"):
        r, raw = session[name], session[f"raw_{name}"]
        assert r.code == 1 and r.out == ""
        assert r.err == f"orccadctl: error: {raw['error']}\n"
    assert session["hold_idle"].err == "orccadctl: error: cannot hold while idle (only when running)\n"


def test_no_daemon_is_one_line_too() -> None:
    r = run("--socket", "/nonexistent/orccadd.sock", "status")
    assert r.code == 2 and r.out == ""
    assert (
        r.err
        == "orccadctl: error: cannot reach orccadd at /nonexistent/orccadd.sock: No such file or directory "
        "(orccadd is not running there, or is still starting up)\n"
    )
    bad = run("--socket", "/nonexistent/orccadd.sock", "tune", "A.b.c", "high")
    assert bad.err == "orccadctl: error: tune: value 'high' is not a number or a JSON list\n"


def test_describe_says_robot_resource_joints_mission_and_tasks(session: dict[str, Any]) -> None:
    idle = session["describe_idle"]
    assert idle.code == 0 and idle.out.startswith("robot ur5e: 6 joints, control period 2 ms (500 Hz)\n")
    assert "\nresource sim_process: active, mode torque, status ok\n" in idle.out
    assert re.search(r"\n  stop categories +0, 1, 2\n", idle.out)
    assert re.search(
        r"\njoints\n  joint +q min rad +q max rad +v max rad/s +a max rad/s\^2 +tau max N.m\n", idle.out
    )
    assert re.search(r"\n  shoulder_pan_joint +-6.283 +6.283 +3.142 ", idle.out)  # sim-ur5e's limits
    assert "\nmission: none loaded" in idle.out
    assert re.search(r"\n  Hold +hold +limit_scale \(fixed\)\n +pd +kp, kd\n", idle.out), idle.out
    text = session["describe"].out
    assert "\nmission PickDemo (" in text and re.search(r"\n  main procedure +PickAndInspect\n", text)
    assert re.search(r"\n  operator inputs +Stop\n", text)
    assert re.search(r"\n  Reach +traj +target_rad, speed_scale\n +ct +kp, kd, ki", text)


def test_json_before_or_after_the_subcommand_is_the_daemons_reply(session: dict[str, Any]) -> None:
    for name in ("describe_json", "describe_json_after"):
        r = session[name]
        reply = json.loads(r.out)
        assert r.code == 0 and reply["ok"] and reply["result"]["robot"] == "ur5e"
        assert reply["result"]["mission"]["name"] == "PickDemo"
    frame = json.loads(session["top_json"].out)
    assert set(frame) == {"status", "events"} and frame["status"]["robot"] == "ur5e"


def test_load_start_tune_hold_resume_stop_reset_abort_in_words(session: dict[str, Any]) -> None:
    load = session["load"].out.splitlines()
    assert load[0] == f"loaded mission PickDemo from {DEMO}; `orccadctl start` runs PickAndInspect"
    assert re.fullmatch(r"mission PickDemo: \d+ states, \d+ transitions", load[1])  # the daemon's report
    assert session["start"].out == "started mission PickDemo (procedure PickAndInspect, run 1)\n"
    assert re.fullmatch(
        r"Reach\.ct\.kp\[2\]: 900 → 500 1/s\^2 \(applied at tick \d+; Reach is not running now: it "
        r"takes effect the next time it runs\)\n",
        session["tune"].out,
    )
    assert session["hold"].out.startswith("holding: the mission is suspended, the Hold task holds the arm")
    assert re.fullmatch(
        r"resumed: (Home|Reach|Inspect|Approach) restarts from the measured state\n", session["resume"].out
    )
    assert session["stop"].out == "stopped: the mission has ended, orccadd is ready\n"
    assert session["reset"].out == "reset: nothing to reset\n"
    assert session["abort"].out.startswith("aborted: safe stop at the next tick")
    assert all(session[n].code == 0 and session[n].err == "" for n in ("load", "start", "tune", "stop"))


def test_params_events_log_status_and_top_in_words(session: dict[str, Any]) -> None:
    params = session["params"].out.splitlines()
    assert params[0] == "Reach"
    assert re.fullmatch(
        r"  traj +target_rad +\[0\.8, -1\.2, 1\.2, -1\.6, -1\.2, 0\.4\] +rad +in ±\[.*\]", params[1]
    )
    assert any(
        re.fullmatch(r"  ct +kp +\[900, 900, 500, 900, 900, 900\] +1/s\^2 +in \[0, 100000\]", x)
        for x in params
    )
    events = session["events"].out.splitlines()
    assert len(events) == 3 and all(re.match(r"\d\d:\d\d:\d\d\.\d{3} t=", x) for x in events)
    assert re.fullmatch(
        r"logging 6 signals to .*/logs/orccadd-[\d-]+\.csv \(`log stop -o FILE` copies it to FILE\)\n",
        session["log_start"].out,
    )
    assert re.fullmatch(r"log: \d+ rows \(0 lost\) in .*\.csv(, MCAP .*\.mcap)?\n", session["log_stop"].out)
    status = session["status"].out.splitlines()
    assert status[0].startswith("ur5e: ready, faulted, mission PickDemo; fault: ")
    top = session["top"].out.splitlines()
    assert top[0].startswith("orccadd top: ur5e") and top[1].startswith("state    running, mission PickDemo")


def test_numbers_and_bounds_are_short() -> None:
    assert num([500.0] * 6) == "500 (×6)" and num([0.8, -1.2]) == "[0.8, -1.2]" and num(1e6) == "1e+06"
    assert bounds([0.0, 100000.0]) == "[0, 100000]"
    assert bounds([[-6.2831, -3.1415], [6.2831, 3.1415]]) == "±[6.2831, 3.1415]"
    assert bounds([[0.0, 0.0], [1.0, 1.0]]) == "[0, 1]"
    assert bounds([[0.0, -1.0], [1.0, 2.0]]) == "[0, -1] .. [1, 2]"


# ---- Ctrl-C -------------------------------------------------------------------------------
ARGV = {
    "check": ["check", "x.mission"], "graph": ["graph", "x.mission", "-o", "x.svg"],
    "export-promela": ["export-promela", "x.mission"], "modules": ["modules"], "status": ["status"],
    "describe": ["describe"], "load": ["load", "x.mission"], "start": ["start"], "stop": ["stop"],
    "abort": ["abort"], "hold": ["hold"], "resume": ["resume"], "reset": ["reset"],
    "send": ["send", "Stop"], "params": ["params"], "tune": ["tune", "A.b.c", "1"],
    "monitor": ["monitor"], "events": ["events", "--follow"], "top": ["top"],
    "log": ["log", "start"], "inject": ["inject", "resource"], "plot": ["plot", "x.csv", "-o", "x.png"],
    "foxglove": ["foxglove", "--port", "0"], "cell": ["cell", "status", "--cell", "x.toml"],
    "move": ["move", "--joints", "0,0,0,0,0,0"], "jog": ["jog", "--joint", "elbow_joint", "--by", "0.1"],
    "follow": ["follow", "x.csv"], "deploy": ["deploy", "x.mission"], "logs": ["logs"],
    "fetch": ["fetch", "x.csv", "-o", "out"], "compare": ["compare", "a.mcap", "b.mcap"],
    "replay": ["replay", "a.mcap"],
}  # fmt: skip


def interrupt(*args: object, **kwargs: object) -> Any:
    raise KeyboardInterrupt


def test_ctrl_c_ends_every_command_quietly_with_130(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    subcommands = set(sub.choices)
    assert subcommands - set(ARGV) == {"completion"}  # a new command gets its line here
    monkeypatch.setattr(online, "Client", interrupt)  # what every online command does first
    monkeypatch.setattr(foxglove, "Client", interrupt)
    monkeypatch.setattr(motion, "Client", interrupt)
    monkeypatch.setattr(ctl_deploy, "Client", interrupt)
    monkeypatch.setattr(ctl_fetch, "Client", interrupt)
    monkeypatch.setattr(compare_cli, "cmd_compare", interrupt)
    monkeypatch.setattr(replayrun, "read_run", interrupt)  # replay's first step: reading the run
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.csv").write_text("t_s,a\n0,0\n1,0.1\n")  # follow reads its file before connecting
    (tmp_path / "x.mission").write_text("mission X\n")  # and deploy its mission
    monkeypatch.setattr(ctl_cell, "open_console", interrupt)
    for name in ("cmd_check", "cmd_graph", "cmd_export", "cmd_modules", "cmd_plot"):
        monkeypatch.setattr(offline, name, interrupt)
    for name, argv in ARGV.items():
        assert run("--socket", "/nonexistent.sock", *argv) == Out(130, "", ""), name


def test_ctrl_c_in_a_stream_exits_130_without_traceback(server: tuple[str, list[float]]) -> None:  # noqa: F811
    path, _ = server
    env = {**os.environ, "ORCCADD_SOCKET": path}
    cmd = [sys.executable, "-m", "orccadd.cli", "monitor", "q"]
    # as from an operator's shell: Ctrl-C at its default (a shell's background job, as under
    # `make test &`, starts with SIGINT ignored, and Python keeps that)
    p = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert p.stdout is not None and p.stdout.readline().split() == ["q.0"]  # streaming
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130 and err == ""


def test_a_resources_details_do_not_repeat_what_its_description_said() -> None:
    """Dynamixel's describe listed the port and the baud rate twice (description, then details)."""
    from orccadd.ctl.human import _resource

    details = {"port": "/dev/ttyUSB0", "baud_rate": 4000000, "reads": 12}
    res = {
        "backend": "dynamixel", "clock": "loop", "modes": ["position"], "mode_switch_needs_disable": True,
        "position": "measured", "velocity": "measured", "torque": "estimated", "brakes": False,
        "stop_categories": [0, 2], "read_time_s": 0.001, "write_time_s": 0.0005, "fault_reset": True,
        "fault_injection": [], "port": "/dev/ttyUSB0", "baud_rate": "4000000",
        "diagnostics": {"lifecycle": "active", "mode": "position", "status": [], "details": details},
    }  # fmt: skip
    text = "\n".join(_resource(res))
    assert text.count("/dev/ttyUSB0") == 1 and text.count("4000000") == 1 and "reads" in text, text
