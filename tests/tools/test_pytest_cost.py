"""The per-test cost plugin's summary: per file, then all."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest

from tools import pytest_cost


def test_the_summary_adds_up_per_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = [
        {"id": "tests/a.py::t1", "wall_s": 2.0, "cpu_s": 1.5, "realtime": True},
        {"id": "tests/a.py::t2[x]", "wall_s": 1.0, "cpu_s": 0.5, "realtime": False},
        {"id": "tests/b.py::t", "wall_s": 4.0, "cpu_s": 4.0, "realtime": True},
    ]
    path = tmp_path / "cost.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert pytest_cost.main([str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split() == ["4.0", "4.0", "1", "1", "tests/b.py"]  # the longest first
    assert lines[2].split() == ["3.0", "2.0", "2", "1", "tests/a.py"]
    assert lines[3].split() == ["7.0", "6.0", "3", "2", "(all)"]


def test_a_realtime_thread_of_this_process_is_seen() -> None:
    done = threading.Event()
    raised = threading.Event()

    def fifo() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except PermissionError:
            pass
        else:
            raised.set()
        done.wait(5)

    t = threading.Thread(target=fifo)
    t.start()
    try:
        if not raised.wait(2):
            pytest.skip("SCHED_FIFO refused (not root)")
        assert pytest_cost._realtime_thread_in(pytest_cost._tree(os.getpid()))
    finally:
        done.set()
        t.join()
