"""`make demo` end to end: daemon up, mission verified and run, tuned, logged, plotted, stopped."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from orccadd import demo


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
