"""The plant's control channel: planes and holes placed from a shell (`python -m orccadd.simctl`),
felt by the arm and published with its state; a bad one refused in the simulator's words. The
plant is stepped by the test (simulated time); only the channel is a socket."""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np
import pytest

from orccadd.kinematics import ToolKinematics
from orccadd.physres.shm_channel import WRENCH_SIZE, PlantChannel
from orccadd.plantsim.control import PlantControl
from orccadd.plantsim.server import PlantServer
from orccadd.robot import load_robot_config
from orccadd.simctl import main as simctl
from orccadd.types import CommandMode
from tests.conftest import UR5E


class Plant:
    def __init__(self, server: PlantServer, control: PlantControl, ch: PlantChannel) -> None:
        self.server, self.control, self.ch, self.t = server, control, ch, 0.0
        self.address = f"127.0.0.1:{control.port}"

    def run(self, seconds: float) -> None:
        for _ in range(int(seconds / self.server.period_s)):
            self.t += self.server.period_s
            self.server.step(self.t)

    def published_wrench(self) -> np.ndarray:
        n3 = 1 + 3 * self.ch.dof
        return self.ch.state[n3 : n3 + WRENCH_SIZE].copy()


@pytest.fixture
def plant() -> Iterator[Plant]:
    cfg = load_robot_config(UR5E)
    ch = PlantChannel(cfg.dof, create=True)
    server = PlantServer(cfg, ch, watchdog_periods=10**6)
    server.arm.activate(CommandMode.POSITION)  # holding where it is
    control = PlantControl(server.arm)
    try:
        yield Plant(server, control, ch)
    finally:
        control.close()
        ch.close(unlink=True)


def test_a_plane_placed_through_the_channel_is_felt_and_published_and_cleared(
    plant: Plant, capsys: pytest.CaptureFixture[str]
) -> None:
    z = ToolKinematics(plant.server.arm.model).pose(plant.server.arm.q).translation[2]
    # a plane 5 mm above the tool, facing up: the tool is in it, pushed up against its servo
    args = ["inject", "plane", f"point_m=[0,0,{z + 0.005}]", "normal=[0,0,1]", "stiffness_n_m=5000"]
    assert simctl([plant.address, *args]) == 0
    plant.run(0.5)
    wrench = plant.published_wrench()
    assert 5.0 < wrench[2] < 5000 * 0.005 + 1.0 and wrench == pytest.approx(plant.server.wrench)
    capsys.readouterr()
    assert simctl([plant.address, "status", "--json"]) == 0
    status = json.loads(capsys.readouterr().out)
    assert [s["shape"] for s in status["world"]["shapes"]] == ["plane"]
    assert (
        status["wrench"][2] == pytest.approx(wrench[2]) and status["devices"][0]["state"] == "active position"
    )
    assert simctl([plant.address, "inject", "clear_world"]) == 0
    plant.run(0.01)
    assert plant.published_wrench() == pytest.approx(np.zeros(6))


def test_a_hole_is_added_beside_a_plane(plant: Plant) -> None:
    args = ["inject", "hole", "center_m=[0.5,0,0]", "normal=[0,0,1]", "radius_m=0.01", "stiffness_n_m=5000"]
    assert simctl([plant.address, *args, "depth_m=0.02"]) == 0
    assert (
        simctl([plant.address, "inject", "plane", "point_m=[0,0,-1]", "normal=[0,0,1]", "stiffness_n_m=1"])
        == 0
    )
    shapes = plant.server.arm.world.describe()["shapes"]
    assert [(s["shape"], s.get("depth_m")) for s in shapes] == [("hole", 0.02), ("plane", None)]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["plane", "point_m=[0,0,0]", "normal=[0,0,0]", "stiffness_n_m=5000"],
            'plane: "normal" (=[0, 0, 0]) must not be zero',
        ),
        (
            ["plane", "point_m=[0,0,0]", "normal=[0,0,1]", "stiffness_n_m=-5"],
            'plane: "stiffness_n_m" (=-5) must be > 0',
        ),
        (["hole", "center_m=[0,0,0]", "normal=[0,0,1]", "stiffness_n_m=5"], 'hole: "radius_m" is required'),
        (["clear_world", "all=true"], "clear_world: unknown parameter(s) all"),
        (["meteor"], "unknown fault 'meteor' (faults: plane, hole, clear_world, occlude, unocclude, target)"),
        (["plane", "--device", "1"], 'the plant is one arm: no "device"'),
    ],
)
def test_a_bad_change_is_refused_in_the_simulators_words(
    plant: Plant, args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert simctl([plant.address, "inject", *args]) == 1
    assert message in capsys.readouterr().err
    assert plant.server.arm.world.shapes == ()
