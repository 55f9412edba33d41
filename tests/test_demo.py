"""`make demo` end to end: daemon up, mission verified and run, tuned, logged, plotted, stopped."""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import pytest

from orccadd import demo
from tests.conftest import ROOT


def test_demo_runs_the_mission_and_writes_log_and_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = set(Path(tempfile.gettempdir()).glob("orccadd-demo-*"))
    assert demo.main(["--out", str(tmp_path)]) == 0
    assert set(Path(tempfile.gettempdir()).glob("orccadd-demo-*")) <= before  # nothing left behind
    assert (tmp_path / "demo.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"  # the log for Foxglove too
    out = capsys.readouterr().out
    assert "mission ended: success" in out and "Inspect.T2.TrackingLost" in out
    assert "tune Approach.traj.speed_scale" in out and "arm at rest, hardware released" in out
    assert (tmp_path / "demo.png").stat().st_size > 1000
    assert len((tmp_path / "demo.csv").read_text().splitlines()) > 1000


def test_make_demo_installs_only_what_the_demo_needs() -> None:
    """`make demo` sets up the Python packages, not the system tools the tests and benchmarks use
    (as root it would apt-install spin, gcc, rt-tests and systemd for nothing)."""
    out = subprocess.run(
        ["make", "-n", "-W", "pyproject.toml", "demo"], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    assert "pip install" in out.stdout and "orccadd.demo" in out.stdout
    assert "apt-get" not in out.stdout and "spin" not in out.stdout
