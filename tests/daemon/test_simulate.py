"""`orccadd --simulate`: a robot's config (its bus named, nothing of it opened) run on the
simulated arm with the same model, limits, period and missions: a UR's config and a Dynamixel
chain's run demo_position.mission to success with no device simulator running."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.robot import load_robot_config, simulated
from tests.daemon.conftest import ROOT, start_daemon_with
from tests.daemon.test_same_mission import local_config


@pytest.mark.parametrize("config", ["ur5e-rtde-sim.toml", "dxl-6axis-sim.toml"])
def test_a_robots_config_runs_its_mission_on_the_simulated_arm(config: str, tmp_path: Path) -> None:
    source = local_config(tmp_path, ROOT / "configs/robots" / config)
    text = source.read_text()
    if "mission_dirs" not in text:  # its default, ../missions, is relative to the config too
        text = text.replace("\n[daemon]\n", f'\n[daemon]\nmission_dirs = ["{ROOT}/configs/missions"]\n', 1)
        source.write_text(text)
    real = load_robot_config(source)
    sim = simulated(real)
    assert sim.resource.backend == "sim" and real.resource.backend != "sim"
    assert (sim.control_period_s, sim.joints, sim.tool, sim.daemon) == (
        real.control_period_s,
        real.joints,
        real.tool,
        real.daemon,
    )
    d = start_daemon_with(tmp_path, source, "--simulate")
    try:
        described = d.call("describe")
        assert described["resource"]["backend"] == "sim_process", described["resource"]  # type: ignore[index]
        assert d.ctl("load", "demo_position").returncode == 0 and d.ctl("start").returncode == 0
        s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
        assert s["result"] == "success" and not s["faulted"], s
    finally:
        d.stop()
    assert simulated(sim) is sim  # a simulated arm stays as it is
