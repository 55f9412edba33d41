"""`orccadctl status` in words: one robot, and a cell's resources each with its own loop."""

from __future__ import annotations

from typing import Any

from orccadd.ctl.format import format_status

JOINT = {"name": "j1", "q_rad": 0.1, "dq_rad_s": 0.0, "tau_nm": 1.5, "cmd": 1.5}
LOOP: dict[str, Any] = {"ticks": 10, "overruns": 0, "switches": 1, "timing": {}, "joints": [JOINT]}
BASE: dict[str, Any] = {
    "robot": "r",
    "state": "running",
    "result": "none",
    "automaton_state": 2,
    "faulted": False,
}


def test_one_robot_has_one_task_line_and_its_joints() -> None:
    text = format_status({**BASE, **LOOP, "active_task": "Move", "task_phase": "run", "resource_status": []})
    assert "active task Move (run), last result none, resource ok" in text
    assert "loop: 10 ticks" in text and "j1" in text


def test_a_cell_names_each_resource_its_task_loop_fault_and_joints() -> None:
    fault = {"event": "Hold_g.T3.ResourceFault", "kind": "device", "resource": "g", "text": "overload"}
    fault |= {"joint": "", "code": 0}
    units = [
        {"name": "arm", "active_task": "Lift", "task_phase": "run", "resource_status": [], **LOOP},
        {"name": "g", "active_task": "Hold_g", "task_phase": "fault", "resource_status": ["stopped"],
         "fault": fault, **LOOP},
    ]  # fmt: skip
    text = format_status({**BASE, **LOOP, "resources": units})
    assert "arm: task Lift (run), resource ok" in text
    assert "g: task Hold_g (fault), resource stopped; fault: " in text and "overload" in text
    assert text.count("  loop: 10 ticks") == 2 and text.count("  j1") == 2
