"""`orccadctl cell status`'s table: a daemon's state and fault in the words its own `status` uses."""

from __future__ import annotations

from orccadd.ctl.cell import status_table

CAUSE = {"event": "Hold.T3.CommLost", "kind": "comm_lost", "resource": "arm", "text": "servo 3 silent",
         "joint": "", "code": 0}  # fmt: skip


def test_a_faulted_daemon_shows_faulted_and_its_cause_in_words() -> None:
    st = {"state": "idle", "faulted": True, "fault": CAUSE, "mission": None, "result": "safe",
          "timing": {"wake_p99_us": 41.0}, "overruns": 0}  # fmt: skip
    line = status_table("demo", {"arm-a": {"ok": True, "result": st}}).splitlines()[-1]
    assert "idle, faulted" in line and "Hold.T3.CommLost (arm: servo 3 silent) (`reset` needed)" in line
    assert "{" not in line and "41 µs" in line


def test_a_cells_resource_fault_is_named_by_resource() -> None:
    st = {"state": "running", "faulted": False, "mission": "M", "result": "none", "timing": None,
          "resources": [{"name": "left", "fault": CAUSE}, {"name": "right", "fault": None}]}  # fmt: skip
    line = status_table("demo", {"arm-a": {"ok": True, "result": st}}).splitlines()[-1]
    assert "left: Hold.T3.CommLost" in line and "right" not in line and "{" not in line
