"""configs/missions/line_demo.mission through orccadd and orccadctl on the simulated arm: the
tool goes out along a straight line 0.3 m and back along it, within a millimetre of the line
throughout, read from the daemon's own full-rate log."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from tests.daemon.conftest import ROOT, Daemon

MISSION = str(ROOT / "configs/missions/line_demo.mission")


def instants(d: Daemon) -> list[tuple[float, tuple[str, ...]]]:
    """The mission's instants: their loop time and the actions taken."""
    events = d.call("events", last=100)["events"]  # type: ignore[index]
    return [(float(e["t_s"]), tuple(e["actions"])) for e in events if e["kind"] == "instant"]


def test_line_demo_keeps_the_tool_within_a_millimetre_of_its_lines(daemon: Daemon, tmp_path: Path) -> None:
    """The daemon runs on tmp_path/robot.toml (tests/daemon/conftest.py: sim-ur5e)."""
    out = tmp_path / "line.csv"
    assert daemon.ctl("log", "start", "q", "--name", "line.csv").returncode == 0
    assert daemon.ctl("load", MISSION).returncode == 0
    assert daemon.ctl("start").returncode == 0
    s = daemon.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success" and not s["faulted"], s
    stop = json.loads(daemon.ctl("log", "stop", "-o", str(out), "--json").stdout)["result"]
    assert stop["lost"] == 0
    starts = {a: t for t, acts in instants(daemon) for a in acts if a.startswith("start ")}
    rows = np.loadtxt(out, delimiter=",", comments="#", skiprows=_header_line(out) + 1)
    t_s, q = rows[:, 0] + float(stop["origin_t_s"]), rows[:, 1:7]
    kin = ToolKinematics(RobotModel.from_config(load_robot_config(tmp_path / "robot.toml")))
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


def _header_line(csv: Path) -> int:
    for i, line in enumerate(csv.read_text().splitlines()):
        if not line.startswith("#"):
            return i
    raise AssertionError(f"{csv} has no header")
