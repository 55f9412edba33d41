"""configs/missions/keepstable_arm.mission through orccadd and orccadctl on the simulated arm's
work cell: the camera servo centres the tool over the target; the target hidden (the plant's
control channel), the arm falls back on holding the tool where it is; shown again, the camera
takes over; the operator's Stop ends it, success."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from orccadd.kinematics import ToolKinematics
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from orccadd.simproc import control_request
from tests.daemon.conftest import ROOT, Daemon, moving, start_daemon_with
from tests.daemon.test_peg_in_hole import workcell

MISSION = str(ROOT / "configs/missions/keepstable_arm.mission")
ABOVE_TARGET = [-0.4919, -0.1233, 0.55]  # 15 cm above the target's centre, where the servo ends


def seen(d: Daemon) -> list[str]:
    events = d.call("events", last=200)["events"]  # type: ignore[index]
    return [x for e in events if e["kind"] == "instant" for x in (*e["inputs"], *e["actions"])]


def tool_at(d: Daemon, kin: ToolKinematics) -> np.ndarray:
    return np.asarray(kin.pose(np.array([j["q_rad"] for j in d.status()["joints"]])).translation)


def test_the_camera_servo_hands_over_to_the_hold_and_back_as_the_target_is_hidden_and_shown(
    tmp_path: Path,
) -> None:
    config = workcell(tmp_path)
    kin = ToolKinematics(RobotModel.from_config(load_robot_config(config)))
    d = start_daemon_with(tmp_path, config)
    try:
        plant = d.call("describe")["resource"]["diagnostics"]["details"]["plant_control"]  # type: ignore[index]
        assert d.ctl("load", MISSION).returncode == 0
        assert d.ctl("start").returncode == 0
        # the servo brings the tool over the target's centre, 15 cm above it, and stays there
        d.wait(lambda s: bool(np.linalg.norm(tool_at(d, kin) - ABOVE_TARGET) < 0.003), timeout_s=60)
        d.wait(lambda s: not moving(s, 0.005), timeout_s=10)
        assert "start KeepStableCam" in seen(d) and np.linalg.norm(tool_at(d, kin) - ABOVE_TARGET) < 0.003
        assert control_request(plant, {"inject": "occlude"}) == {"ok": True}
        d.wait(
            lambda s: "start KeepStableUS" in seen(d)[seen(d).index("start KeepStableCam") :], timeout_s=10
        )
        held = tool_at(d, kin)
        assert "KeepStableCam.T2.UnStableCam" in seen(d)
        assert control_request(plant, {"inject": "unocclude"}) == {"ok": True}
        d.wait(lambda s: seen(d).count("start KeepStableCam") == 2, timeout_s=10)
        assert "KeepStableUS.T2.Stabilized" in seen(d)
        assert np.linalg.norm(tool_at(d, kin) - held) < 0.002  # held where the camera lost it
        assert d.ctl("send", "Stop").returncode == 0
        s = d.wait(lambda s: s["state"] != "running", timeout_s=10)
        assert s["result"] == "success" and not s["faulted"], s
    finally:
        d.stop()
