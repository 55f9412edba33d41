"""configs/missions/peg_in_hole.mission through orccadd and orccadctl on the simulated arm in
its work cell (configs/robots/sim-ur5e-workcell.toml: a table with a hole): the peg comes down
beside the axis, touches the rim, is inserted 2 cm by hybrid force control and retreats; with
the hole gone (the plant's control channel: a plain table), the insertion is `Missed`, the peg
is lifted clear and the safe procedure waits for the operator. The same mission on the UR
controller simulator, given the same hole."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from orccadd.simproc import control_request
from orccadd.ursim.process import UrSimProcess
from tests.daemon.conftest import ROOT, Daemon, log_rows, start_daemon_with
from tests.daemon.test_same_mission import local_config

MISSION = str(ROOT / "configs/missions/peg_in_hole.mission")
WORKCELL = ROOT / "configs/robots/sim-ur5e-workcell.toml"
UR = ROOT / "configs/robots/ur5e-rtde-sim.toml"
HOLE = {
    "center_m": [-0.4919, -0.2333, 0.4],
    "normal": [0, 0, 1],
    "radius_m": 0.01,
    "depth_m": 0.03,
    "stiffness_n_m": 5000.0,
}


def workcell(tmp: Path) -> Path:
    """The work cell's config with its paths made absolute, written under `tmp`."""
    text = WORKCELL.read_text().replace('"../', f'"{ROOT}/configs/')
    defaults = f'hold_task = "{ROOT}/configs/tasks/hold.toml"\ntask_dirs = ["{ROOT}/configs/tasks"]\n'
    path = tmp / WORKCELL.name
    path.write_text(text.replace("\n[daemon]\n", "\n[daemon]\n" + defaults, 1))
    return path


def actions(d: Daemon) -> list[str]:
    events = d.call("events", last=100)["events"]  # type: ignore[index]
    return [x for e in events if e["kind"] == "instant" for x in (*e["inputs"], *e["actions"])]


def test_the_peg_goes_in_and_comes_out(tmp_path: Path) -> None:
    config = workcell(tmp_path)
    d = start_daemon_with(tmp_path, config)
    try:
        out = tmp_path / "peg.csv"
        assert d.ctl("log", "start", "--name", "peg.csv").returncode == 0  # all a replay needs
        assert d.ctl("load", MISSION).returncode == 0
        assert d.ctl("start").returncode == 0
        s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
        assert s["result"] == "success" and not s["faulted"], (s, actions(d))
        done = [a for a in actions(d) if a.endswith(".done")]
        assert done == ["Home.done", "Above.done", "Touch.done", "Insert.done", "Retreat.done"], done
        stop = json.loads(d.ctl("log", "stop", "-o", str(out), "--json").stdout)["result"]
        header = next(x for x in out.read_text().splitlines() if not x.startswith("#")).split(",")
        assert [c for c in header if c.startswith("wrench.")] == [f"wrench.{k}" for k in range(6)]
        q = log_rows(out)[:, [i for i, c in enumerate(header) if c.startswith("q.")]]
        kin = ToolKinematics(RobotModel.from_config(load_robot_config(config)))
        tool = np.array([kin.pose(qi).translation for qi in q])
        deepest = tool[tool[:, 2].argmin()]
        assert deepest[2] < 0.381 and stop["lost"] == 0  # 2 cm into the hole, whose mouth is at 0.4
        assert np.linalg.norm(deepest[:2] - [-0.4919, -0.2333]) < 0.0025  # within its 2 mm of play
        # the force-controlled tasks read the sensor's wrench: logged, it replays bit for bit
        r = d.ctl("replay", "--json", str(out.with_suffix(".mcap")))
        rep = json.loads(r.stdout)
        assert r.returncode == 0 and rep["identical"], r.stdout + r.stderr
        assert [t["task"] for t in rep["tasks"]] == ["Home", "Above", "Touch", "Insert", "Retreat"]
        assert not rep["notes"], rep["notes"]  # the wrench in the log, nothing replayed as zeros
    finally:
        d.stop()


def test_beside_the_hole_the_insertion_is_missed_and_the_peg_lifted_clear(tmp_path: Path) -> None:
    config = workcell(tmp_path)
    d = start_daemon_with(tmp_path, config)
    try:
        plant = d.call("describe")["resource"]["diagnostics"]["details"]["plant_control"]  # type: ignore[index]
        assert control_request(plant, {"inject": "clear_world"}) == {"ok": True}
        table = {"point_m": [0.0, 0.0, 0.4], "normal": [0.0, 0.0, 1.0], "stiffness_n_m": 5000.0}
        assert control_request(plant, {"inject": "plane", **table}) == {"ok": True}
        assert d.ctl("load", MISSION).returncode == 0
        assert d.ctl("start").returncode == 0
        d.wait(lambda s: "Lift.done" in actions(d), timeout_s=60)
        seen = actions(d)
        assert "Insert.T2.Missed" in seen and "safe" in seen and "Retreat.done" not in seen, seen
        assert d.ctl("send", "Stop").returncode == 0
        s = d.wait(lambda s: s["state"] != "running", timeout_s=10)
        assert not s["faulted"], s
    finally:
        d.stop()


def test_the_same_mission_on_the_ur_simulator(tmp_path: Path) -> None:
    """On the UR controller simulator (servoJ, its TCP the flange): its world given the same hole
    and peg through its control channel; the same insertion."""
    with UrSimProcess(UR, "--boot", "running", "--priority", "70") as ur:
        ur.inject("tool", radius_m=0.008)
        ur.inject("hole", **HOLE)
        config = local_config(tmp_path, UR)
        d = start_daemon_with(tmp_path, config)
        try:
            out = tmp_path / "peg.csv"
            assert d.ctl("log", "start", "--name", "peg.csv").returncode == 0  # all a replay needs
            assert d.ctl("load", MISSION).returncode == 0
            assert d.ctl("start").returncode == 0
            s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
            assert s["result"] == "success" and not s["faulted"], (s, actions(d))
            d.ctl("log", "stop", "-o", str(out), "--json")
            kin = ToolKinematics(RobotModel.from_config(load_robot_config(config)))
            tool = np.array([kin.pose(qi).translation for qi in log_rows(out)[:, 1:7]])
            assert tool[:, 2].min() < 0.381
        finally:
            d.stop()
