"""configs/missions/line_demo.mission through orccadd and orccadctl on the simulated arm and on
the UR controller simulator (servoJ): the tool goes out along a straight line 0.3 m and back
along it, within a millimetre of the line throughout, read from the daemon's own full-rate log."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from tests.daemon.conftest import ROOT, Daemon, log_rows, start_daemon_with
from tests.daemon.test_same_mission import arm_config

MISSION = str(ROOT / "configs/missions/line_demo.mission")


def instants(d: Daemon) -> list[tuple[float, tuple[str, ...]]]:
    """The mission's instants: their loop time and the actions taken."""
    events = d.call("events", last=100)["events"]  # type: ignore[index]
    return [(float(e["t_s"]), tuple(e["actions"])) for e in events if e["kind"] == "instant"]


@pytest.mark.parametrize("backend", ["sim", "ur_rtde"])
def test_line_demo_keeps_the_tool_within_a_millimetre_of_its_lines(backend: str, tmp_path: Path) -> None:
    with arm_config(backend, tmp_path) as config:
        daemon = start_daemon_with(tmp_path, config)
        try:
            check_line_demo(daemon, config, tmp_path)
        finally:
            daemon.stop()


def check_line_demo(daemon: Daemon, config: Path, tmp_path: Path) -> None:
    out = tmp_path / "line.csv"
    assert daemon.ctl("log", "start", "q", "--name", "line.csv").returncode == 0
    assert daemon.ctl("load", MISSION).returncode == 0
    assert daemon.ctl("start").returncode == 0
    s = daemon.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success" and not s["faulted"], s
    stop = json.loads(daemon.ctl("log", "stop", "-o", str(out), "--json").stdout)["result"]
    assert stop["lost"] == 0
    starts = {a: t for t, acts in instants(daemon) for a in acts if a.startswith("start ")}
    rows = log_rows(out)
    t_s, q = rows[:, 0] + float(stop["origin_t_s"]), rows[:, 1:7]
    kin = ToolKinematics(RobotModel.from_config(load_robot_config(config)))
    tool = np.array([kin.pose(qi).translation for qi in q])
    out_t, back_t = starts["start Out"], starts["start Back"]
    at_out = tool[np.searchsorted(t_s, out_t)]
    lines = ((out_t, back_t, at_out + np.array([0.0, -0.3, 0.0])), (back_t, t_s[-1], at_out))
    for first, last, goal in lines:
        seg = tool[(t_s >= first) & (t_s <= last)]
        start = seg[0]
        u = (goal - start) / np.linalg.norm(goal - start)
        d = seg - start
        off_line = np.linalg.norm(d - np.outer(d @ u, u), axis=1)
        assert off_line.max() < 1e-3, off_line.max()
        assert np.linalg.norm(seg[-1] - goal) < 2e-3  # each line's goal, from where it began
    assert np.linalg.norm(tool[-1] - at_out) < 2e-3  # back where it went out from
