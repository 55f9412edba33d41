"""The plant's camera through its control channel: an occluder put and taken away, the target
moved, from a shell (`python -m orccadd.simctl`); what the camera sees published with the state
(features, then target_visible, after the wrench); a plant without a camera refuses them. The
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
from orccadd.robot import load_robot_config, with_backend
from orccadd.simctl import main as simctl
from orccadd.types import CommandMode
from tests.conftest import UR5E
from tests.plantsim.test_control import Plant

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


def square(tool: np.ndarray, dx_m: float = 0.0) -> list[list[float]]:
    """A 6 cm square 30 cm below the tool (at home: ahead of the camera), `dx_m` along the base's x."""
    corners = [(-0.03, -0.03), (-0.03, 0.03), (0.03, 0.03), (0.03, -0.03)]
    return [[float(tool[0] + dx_m + x), float(tool[1] + y), float(tool[2] - 0.3)] for x, y in corners]


@pytest.fixture
def plant() -> Iterator[Plant]:
    cfg = with_backend(load_robot_config(UR5E), "sim", initial_q_rad=HOME, camera={})
    ch = PlantChannel(cfg.dof, create=True)
    server = PlantServer(cfg, ch, watchdog_periods=10**6)
    server.arm.activate(CommandMode.POSITION)  # holding where it is
    control = PlantControl(server.arm)
    try:
        yield Plant(server, control, ch)
    finally:
        control.close()
        ch.close(unlink=True)


def published(plant: Plant) -> tuple[np.ndarray, float]:
    camera = plant.ch.state[1 + 3 * plant.ch.dof + WRENCH_SIZE :]
    return camera[:-1].copy(), float(camera[-1])


def test_the_target_set_occluded_and_uncovered_through_the_channel_is_published(
    plant: Plant, capsys: pytest.CaptureFixture[str]
) -> None:
    plant.run(0.01)
    assert published(plant) == (pytest.approx(np.zeros(8)), 0.0)  # no target yet: nothing seen
    tool = ToolKinematics(plant.server.arm.model).pose(plant.server.arm.q).translation
    assert simctl([plant.address, "inject", "target", f"points_m={json.dumps(square(tool))}"]) == 0
    plant.run(0.01)
    features, visible = published(plant)
    # at home the image's x is the base's y, its y the base's x: the corners at (±0.1, ±0.1)
    goal = [-0.1, -0.1, 0.1, -0.1, 0.1, 0.1, -0.1, 0.1]
    assert visible == 1.0 and features == pytest.approx(goal, abs=1e-3)
    assert simctl([plant.address, "inject", "occlude"]) == 0
    plant.run(0.01)
    assert published(plant) == (pytest.approx(features), 0.0)  # the last seen values kept
    capsys.readouterr()
    assert simctl([plant.address, "status", "--json"]) == 0
    camera = json.loads(capsys.readouterr().out)["camera"]
    assert camera["occluded"] and not camera["target_visible"] and camera["focal_px"] == 600.0
    assert simctl([plant.address, "inject", "unocclude"]) == 0
    plant.run(0.01)
    assert published(plant) == (pytest.approx(features), 1.0)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["target", "points_m=[[0,0,0]]"], 'target: "points_m" (=[[0, 0, 0]]) must be 4 points [x, y, z]'),
        (["target"], 'target: "points_m" is required'),
        (["occlude", "on=true"], "occlude: unknown parameter(s) on"),
    ],
)
def test_a_bad_change_of_the_scene_is_refused_in_the_simulators_words(
    plant: Plant, args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert simctl([plant.address, "inject", *args]) == 1
    assert message in capsys.readouterr().err


def test_a_plant_without_a_camera_refuses_its_changes_and_publishes_zeros(
    capsys: pytest.CaptureFixture[str],
) -> None:
    cfg = load_robot_config(UR5E)
    ch = PlantChannel(cfg.dof, create=True)
    server = PlantServer(cfg, ch, watchdog_periods=10**6)
    control = PlantControl(server.arm)
    try:
        plant = Plant(server, control, ch)
        assert simctl([plant.address, "inject", "occlude"]) == 1
        assert "occlude: the arm has no camera" in capsys.readouterr().err
        plant.run(0.01)
        assert published(plant) == (pytest.approx(np.zeros(8)), 0.0)
    finally:
        control.close()
        ch.close(unlink=True)
