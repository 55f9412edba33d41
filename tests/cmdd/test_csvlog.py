"""The log directory's files: created once, reopened after a crash cut at the last complete row,
the state file never read or written through a link."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from orccadd.cmdd.csvlog import STATE_FILE, CsvTail, LogDir


def test_a_log_cut_mid_row_is_reopened_after_its_last_complete_row(tmp_path: Path) -> None:
    d = LogDir(tmp_path / "logs", "")
    head = "# orccadd log {}\n# units {}\n# time_s: ...\ntime_s,q.j1\n"
    with d.create("run.csv") as fh:  # killed mid-row, an event after the last row
        fh.write(
            head
            + "# event,0.002000,7,command,start,\n0.002000,1\n0.004000,2\n# event,0.004,9,event,x,\n0.0060"
        )
    fh2, tail = d.reopen("run.csv")
    with fh2:
        fh2.write("0.006000,3\n")
    assert tail == CsvTail(last_time_s=0.004, rows=2, last_event_seq=9)
    text = (tmp_path / "logs/run.csv").read_text()
    assert text.startswith(head) and text.endswith("0.004000,2\n# event,0.004,9,event,x,\n0.006000,3\n")
    with d.create("empty.csv") as fh:
        fh.write(head)
    assert d.reopen("empty.csv")[1] == CsvTail(float("-inf"), 0, -1)


def test_the_state_file_round_trips_and_is_never_followed_through_a_link(tmp_path: Path) -> None:
    d = LogDir(tmp_path / "logs", "")
    assert d.load_state() is None
    d.save_state({"file": "run.csv", "rt_pid": 7})
    assert d.load_state() == {"file": "run.csv", "rt_pid": 7}
    d.clear_state()
    victim = tmp_path / "victim.json"
    victim.write_text('{"file": "planted.csv"}')
    os.symlink(victim, tmp_path / "logs" / STATE_FILE)
    assert d.load_state() is None  # O_NOFOLLOW
    d.save_state({"file": "run.csv"})  # replaces the link, does not write through it
    assert victim.read_text() == '{"file": "planted.csv"}'
    assert not (tmp_path / "logs" / STATE_FILE).is_symlink()


@pytest.mark.parametrize("name", ["../x.csv", ".active-log.json", "x.txt", "a/b.csv"])
def test_only_log_names_are_created_or_reopened(tmp_path: Path, name: str) -> None:
    d = LogDir(tmp_path / "logs", "")
    with pytest.raises(ValueError):
        d.create(name)
    with pytest.raises(ValueError):
        d.reopen(name)
