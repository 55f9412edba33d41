"""One console for every daemon of a cell: three daemons (separate processes), a console peer
over loopback TLS, `orccadctl cell status`, `--robot NAME COMMAND`, roles from certificates."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cellnet.conftest import Member, console_file

ORCCADCTL = [sys.executable, "-m", "orccadd.cli"]


def ctl(*argv: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*ORCCADCTL, *argv], capture_output=True, text=True, timeout=timeout_s, check=False)


def test_the_console_sees_every_daemon_and_commands_one(
    tmp_path: Path, certs: Path, cell_of_three: list[Member]
) -> None:
    console = console_file(tmp_path, "test", "console", certs, [cell_of_three[0].endpoint])
    r = ctl("--cell", str(console), "cell", "status", "--json")
    assert r.returncode == 0, r.stderr
    robots = json.loads(r.stdout)["robots"]
    assert sorted(robots) == ["arm-a", "arm-b", "arm-c"]
    assert all(v["ok"] and v["result"]["state"] == "idle" for v in robots.values()), robots
    words = ctl("--cell", str(console), "cell", "status")
    assert "arm-b" in words.stdout and "idle" in words.stdout, words
    r = ctl("--cell", str(console), "--robot", "arm-b", "--json", "load", "demo")
    assert json.loads(r.stdout)["ok"], r.stdout + r.stderr
    described = json.loads(ctl("--cell", str(console), "--robot", "arm-b", "--json", "describe").stdout)
    assert described["result"]["mission"]["name"] == "PickDemo"  # demo.mission's module
    other = json.loads(ctl("--cell", str(console), "--robot", "arm-c", "--json", "describe").stdout)
    assert other["result"]["mission"] is None  # only arm-b loaded it
    merged = [
        json.loads(x)
        for x in ctl("--cell", str(console), "cell", "events", "--json", "--last", "5").stdout.splitlines()
    ]
    assert [e["robot"] for e in merged if e.get("command") == "load"] == ["arm-b"], merged
    assert [e["wall_s"] for e in merged] == sorted(e["wall_s"] for e in merged)  # one time order
    top = json.loads(ctl("--cell", str(console), "cell", "top", "--json", "--count", "1").stdout)
    assert sorted(top["robots"]) == ["arm-a", "arm-b", "arm-c"] and top["lost"] == []


def test_a_read_only_peer_reads_and_cannot_command(
    tmp_path: Path, certs: Path, cell_of_three: list[Member]
) -> None:
    viewer = console_file(tmp_path, "test", "viewer", certs, [cell_of_three[0].endpoint])
    r = ctl("--cell", str(viewer), "--robot", "arm-a", "--json", "status")
    assert json.loads(r.stdout)["ok"], r.stdout + r.stderr
    for argv in (["load", "demo"], ["abort"], ["start"], ["tune", "hold.pd.kp", "1"]):
        r = ctl("--cell", str(viewer), "--robot", "arm-a", *argv)
        assert r.returncode != 0 and "not authorised" in r.stderr, (argv, r.stderr)
    assert cell_of_three[0].daemon.call("describe")["mission"] is None  # nothing loaded


def test_peers_without_a_listed_or_valid_certificate_get_nothing(
    tmp_path: Path, certs: Path, cell_of_three: list[Member]
) -> None:
    from orccadd.cellnet.certs import make_cell_certs
    from orccadd.cellnet.console import CellConsole, CellError, read_console_config

    endpoint = [cell_of_three[0].endpoint]
    stranger = console_file(tmp_path, "test", "stranger", certs, endpoint)  # the CA's, not listed
    rogue_dir = make_cell_certs(tmp_path / "rogue", ["console"])  # a console's name, another CA
    rogue = console_file(tmp_path, "test", "console", rogue_dir, endpoint)
    plain = tmp_path / "plain.toml"  # no TLS at all: a tcp endpoint to a TLS listener
    plain.write_text(
        f'[cell]\nname = "test"\nrobot = "plain"\nconnect = ["{endpoint[0].replace("tls/", "tcp/")}"]\n'
    )
    commands = [
        ("load", {"path": "demo"}),
        ("start", {}),
        ("tune", {"path": "Hold.pd.kp", "value": 1}),
        ("abort", {}),
    ]
    for who in (stranger, rogue):
        with CellConsole(read_console_config(str(who))) as console:
            assert console.robots(wait_s=0.5) == [], who
            for cmd, args in commands:
                r = console.request("arm-a", cmd, timeout_s=1.0, **args)
                assert not r["ok"], (who, cmd, r)
                assert "not in cell" in r["error"] or "reaches no peer" in r["error"], (who, cmd, r)
    with CellConsole(read_console_config(str(plain))) as console:  # nothing to send a command with
        assert console.robots(wait_s=0.5) == []
        assert "reaches no peer" in console.request("arm-a", "status", timeout_s=1.0)["error"]
        for cmd, args in commands[:1]:
            with pytest.raises(CellError, match="no TLS"):
                console.request("arm-a", cmd, timeout_s=1.0, **args)
    r = ctl("--cell", str(stranger), "--robot", "arm-a", "abort")  # as orccadctl says it
    assert r.returncode != 0 and "abort NOT confirmed by arm-a" in r.stderr, r.stderr
    assert "not in cell 'test'" in r.stderr, r.stderr
    for m in cell_of_three:  # nothing loaded, nothing moved, nothing stopped
        st = m.daemon.status()
        assert st["state"] == "idle" and st["mission"] is None and not st["faulted"], st
