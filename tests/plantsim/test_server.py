"""The plant process's stepping: a stall of the process pauses the simulated world."""

from __future__ import annotations

import numpy as np

from orccadd.physres.shm_channel import PlantChannel
from orccadd.plantsim.server import PAUSE_AFTER_PERIODS, PlantServer
from orccadd.robot import load_robot_config
from orccadd.types import CommandMode
from tests.conftest import UR5E


def test_a_stalled_plant_process_pauses_the_world_instead_of_integrating_a_stale_command() -> None:
    cfg = load_robot_config(UR5E)
    ch = PlantChannel(cfg.dof, create=True)
    try:
        server = PlantServer(cfg, ch, watchdog_periods=10**6)
        server.arm.activate(CommandMode.TORQUE)  # no torque: the arm falls under gravity
        period = cfg.control_period_s
        t = 0.0
        for _ in range(50):
            t += period
            server.step(t)
        dq_before = np.abs(server.arm.dq).max()
        t += 0.2  # the process did not run for 0.2 s (100 periods)
        server.step(t)
        assert server.paused_s > 0.19
        # one period of falling was integrated, not a hundred: the speed barely changed
        assert np.abs(server.arm.dq).max() < dq_before + 20 * period * 9.81
        t += PAUSE_AFTER_PERIODS * period * 0.5  # a late step, not a stall: integrated in full
        paused = server.paused_s
        server.step(t)
        assert server.paused_s == paused
    finally:
        ch.close()
