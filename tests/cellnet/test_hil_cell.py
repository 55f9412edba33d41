"""Hardware in the loop over the cell, from one console: a mission deployed to a daemon over Zenoh
(control role), loaded by name, run, logged, its log listed and fetched back (read role), then
compared with a run on the console's side of the loop and replayed. The same commands as over the
socket (tests/daemon/test_deploy.py, test_fetch.py), through `--cell` and `--robot`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.cellnet.conftest import console_file, start_member
from tests.daemon.conftest import ROOT

ORCCADCTL = [sys.executable, "-m", "orccadd.cli"]
MISSION = str(ROOT / "configs/missions/demo_position.mission")


def ctl(*argv: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*ORCCADCTL, *argv], capture_output=True, text=True, timeout=timeout_s, check=False)


def test_deploy_run_fetch_compare_and_replay_over_the_cell(tmp_path: Path, certs: Path) -> None:
    arm = start_member(tmp_path, "test", "arm-a", certs, [], control=("console",), read=("viewer",))
    try:
        console = console_file(tmp_path, "test", "console", certs, [arm.endpoint], daemons=("arm-a",))
        viewer = console_file(tmp_path, "test", "viewer", certs, [arm.endpoint], daemons=("arm-a",))
        on = ("--cell", str(console), "--robot", "arm-a")
        # a reader may not deploy; the console may, and the daemon keeps it by its hash
        refused = ctl("--cell", str(viewer), "--robot", "arm-a", "deploy", MISSION, "--name", "hil")
        assert refused.returncode != 0 and "not authorised" in refused.stderr, refused.stderr
        r = ctl(*on, "deploy", MISSION, "--name", "hil", "--json")
        assert r.returncode == 0, r.stdout + r.stderr
        deployed = json.loads(r.stdout)["result"]["deployed"]
        for run in ("first", "second"):
            assert ctl(*on, "load", "hil").returncode == 0
            assert ctl(*on, "log", "start", "--name", f"{run}.csv").returncode == 0
            r = ctl(*on, "start", "--wait")
            assert r.returncode == 0, r.stdout + r.stderr
            assert ctl(*on, "log", "stop").returncode == 0
        described = json.loads(ctl(*on, "--json", "describe").stdout)["result"]
        assert described["mission"]["deployment"] == deployed
        # the logs come back to the console over the cell; reading them takes the read role only
        listed = json.loads(ctl("--cell", str(viewer), "--robot", "arm-a", "--json", "logs").stdout)
        names = [x["name"] for x in listed["logs"]]
        assert {"first.csv", "second.csv"} <= set(names), names
        out = tmp_path / "runs"
        for run in ("first", "second"):
            r = ctl("--cell", str(viewer), "--robot", "arm-a", "fetch", f"{run}.csv", "-o", str(out))
            assert r.returncode == 0, r.stdout + r.stderr
        # the first run moved the arm home from where it stood: the second, from home, is the
        # reference a CI job keeps; the same mission, the same reactive trace
        r = ctl("compare", "--json", str(out / "first.mcap"), str(out / "second.mcap"))
        rep = json.loads(r.stdout)
        assert r.returncode in (0, 1) and rep["trace"]["same"], r.stdout
        assert rep["mission"]["a"] == rep["mission"]["b"] == "PositionDemo"
        r = ctl("replay", "--json", str(out / "second.mcap"))
        assert r.returncode == 0 and json.loads(r.stdout)["identical"], r.stdout + r.stderr
    finally:
        arm.daemon.stop()
