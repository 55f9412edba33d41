"""`orccadd --mission`: the mission is compiled while the arm is already held; a bad one stops
the daemon before it serves anyone, with the reason and exit code 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.daemon.conftest import ROOT, robot_config, start_daemon

DEMO = str(ROOT / "configs/missions/demo.mission")


def test_a_startup_mission_is_loaded_and_waits_for_start(tmp_path: Path) -> None:
    d = start_daemon(tmp_path, "--mission", DEMO)
    try:
        s = d.status()
        assert s["state"] == "ready" and s["mission"] == "PickDemo" and not s["faulted"], s
        assert int(s["ticks"]) > 0  # type: ignore[call-overload]
    finally:
        d.stop()


def test_a_bad_startup_mission_stops_the_daemon_with_the_reason(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mission"
    bad.write_text("mission Bad\nresource arm\nprocedure Main main\n  await Nothing\nend\n")
    cmd = [
        sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(robot_config(tmp_path)),
        "--socket", str(tmp_path / "run/orccadd.sock"), "--mission", str(bad),
    ]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "bad.mission:" in out.stderr
    assert not (tmp_path / "run/orccadd.sock").exists()


def test_a_squatted_socket_path_stops_the_daemon_before_anything_starts(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir(mode=0o750)
    (run / "orccadd.sock").write_text("not a socket")
    cmd = [
        sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(robot_config(tmp_path)),
        "--socket", str(run / "orccadd.sock"),
    ]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "is not a socket" in out.stderr, out.stderr
    assert (run / "orccadd.sock").read_text() == "not a socket"  # left as it was
