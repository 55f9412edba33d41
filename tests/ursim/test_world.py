"""The world the tool touches (a wall, a push), the flange's force/torque sensor and the contact
history behind tool_contact, each on its own."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.ursim.ft_sensor import G_M_S2, FtSensor
from orccadd.ursim.tool_contact import THRESHOLD_N, ContactHistory
from orccadd.ursim.world import World, push_from_params, wall_from_params


def floor(stiffness: float = 5000.0, damping: float = 100.0) -> World:
    w = World()
    w.wall = wall_from_params(
        {"point_m": [0, 0, 0.1], "normal": [0, 0, 2], "stiffness_n_m": stiffness, "damping_n_s_m": damping}
    )
    return w


def wrench(w: World, p: list[float], v: list[float]) -> tuple[bool, np.ndarray]:
    out = np.zeros(6)
    touched = w.wrench_at(np.array(p), np.array(v), out)
    return touched, out


def test_the_wall_pushes_out_along_its_normal_by_depth_and_speed() -> None:
    w = floor()
    assert w.wall is not None and w.wall.normal == (0.0, 0.0, 1.0)  # normalised
    assert wrench(w, [0.3, 0.2, 0.11], [0, 0, -1]) == (False, pytest.approx(np.zeros(6)))  # outside
    touched, f = wrench(w, [0.3, 0.2, 0.098], [0.0, 0.0, 0.0])  # 2 mm in, at rest
    assert touched and f == pytest.approx([0, 0, 10.0, 0, 0, 0])
    _, f = wrench(w, [0.0, 0.0, 0.098], [0.5, 0.0, -0.05])  # moving in: 100 N·s/m × 0.05 m/s more
    assert f == pytest.approx([0, 0, 15.0, 0, 0, 0])  # no friction: the sideways speed adds nothing
    _, f = wrench(w, [0.0, 0.0, 0.098], [0.0, 0.0, 0.5])  # leaving fast: it never pulls
    assert f == pytest.approx(np.zeros(6))


def test_a_push_acts_until_its_duration_ends() -> None:
    w = World()
    w.now_s = 10.0
    w.push = push_from_params({"force_n": [20, 0, 0], "torque_nm": [0, 0, 1], "duration_s": 0.5}, w.now_s)
    assert wrench(w, [0, 0, 0], [0, 0, 0]) == (True, pytest.approx([20, 0, 0, 0, 0, 1]))
    w.now_s = 10.6
    assert wrench(w, [0, 0, 0], [0, 0, 0])[0] is False
    assert w.push is None and w.describe() == {
        "wall": None,
        "push_active": False,
        "shapes": 0,
        "tool_radius_m": 0.0,
    }


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"point_m": [0, 0, 0], "normal": [0, 0, 0], "stiffness_n_m": 1}, "normal"),
        ({"point_m": [0, 0], "normal": [0, 0, 1], "stiffness_n_m": 1}, "point_m"),
        ({"point_m": [0, 0, 0], "normal": [0, 0, 1], "stiffness_n_m": -5}, "stiffness_n_m"),
        ({"point_m": [0, 0, 0], "normal": [0, 0, 1], "stiffness_n_m": 5, "stifness": 1}, "unknown"),
        ({"point_m": [0, 0, 0], "normal": [0, 0, 1]}, "stiffness_n_m"),
    ],
)
def test_a_bad_wall_is_refused_naming_the_parameter(params: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        wall_from_params(params)


def test_the_sensor_reports_the_change_since_zeroing_and_the_raw_wrench_with_the_payload() -> None:
    force, raw = np.zeros(6), np.zeros(6)
    sensor = FtSensor(force, raw)
    contact = np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    sensor.measure(contact, 2.0, np.array([0.1, 0.0, 0.0]))
    assert force == pytest.approx(contact)  # the payload's weight compensated
    weight = -2.0 * G_M_S2
    assert raw == pytest.approx([0, 0, 10.0 + weight, 0, -0.1 * weight, 0])  # r × F of the weight
    sensor.zero()
    sensor.measure(contact, 2.0, np.zeros(3))
    assert force == pytest.approx(np.zeros(6))
    sensor.measure(np.zeros(6), 2.0, np.zeros(3))  # contact lost after zeroing in it
    assert force == pytest.approx(-contact)


def test_the_sensors_noise_is_seeded() -> None:
    readings = []
    for _ in range(2):
        force = np.zeros(6)
        sensor = FtSensor(force, np.zeros(6))
        sensor.set_noise(0.5, 0.01, seed=7)
        sensor.measure(np.zeros(6), 0.0, np.zeros(3))
        readings.append(force.copy())
    assert readings[0] == pytest.approx(readings[1]) and np.abs(readings[0]).max() > 0.0
    with pytest.raises(ValueError, match="must be >= 0"):
        FtSensor(np.zeros(6), np.zeros(6)).set_noise(-1.0, 0.0, 0)


def test_tool_contact_counts_the_cycles_since_the_contact_began() -> None:
    h = ContactHistory(cycles=50)
    down = np.array([0.0, 0.0, -1.0])
    for _ in range(10):
        h.record(np.zeros(3))
    assert h.steps_in_contact(down) == 0
    for k in range(1, 4):
        h.record(np.array([0.0, 0.0, THRESHOLD_N + 1.0]))  # the floor pushes up: moving down
        assert h.steps_in_contact(down) == k
    assert h.steps_in_contact(-down) == 0  # not against a motion upwards
    assert h.steps_in_contact(np.zeros(3)) == 3  # any direction
    for _ in range(60):
        h.record(np.array([0.0, 0.0, THRESHOLD_N + 1.0]))
    assert h.steps_in_contact(down) == 50  # at most the history's length


def test_the_simulated_arms_world_settings_are_refused_for_the_ur_simulators_arm() -> None:
    """The UR simulator's world is its wall (control channel); the `sim` backend's planes (and
    camera) in its `--plant` settings would do nothing there, so they are refused, naming the key."""
    from orccadd.config.robot import read_robot_config
    from orccadd.errors import ConfigError
    from orccadd.ursim.arm import UrArm
    from tests.ursim.conftest import UR5E_RTDE

    plane = {"point_m": [0, 0, 0.1], "normal": [0, 0, 1], "stiffness_n_m": 5000.0}
    with pytest.raises(ConfigError, match=r"plant.toml: world_planes is the simulated arm's: .*\(wall\)"):
        UrArm(read_robot_config(UR5E_RTDE), 0.002, {"world_planes": [plane]}, "plant.toml")
    with pytest.raises(
        ConfigError, match=r"plant.toml: camera is the simulated arm's: the UR simulator has none"
    ):
        UrArm(read_robot_config(UR5E_RTDE), 0.002, {"camera": {}}, "plant.toml")


def test_a_hole_takes_a_tcp_sphere_on_its_axis_and_holds_one_beside_it() -> None:
    w = World()
    w.change("tool", {"radius_m": 0.008})
    hole = {
        "center_m": [0.4, 0.0, 0.1],
        "normal": [0, 0, 1],
        "radius_m": 0.01,
        "depth_m": 0.03,
        "stiffness_n_m": 5000,
    }
    w.change("hole", hole)
    assert not w.empty and w.describe()["shapes"] == 1 and w.describe()["tool_radius_m"] == 0.008
    assert wrench(w, [0.4, 0.0, 0.09], [0, 0, 0])[0] is False  # on the axis, 1 cm in: 2 mm of play
    touched, f = wrench(w, [0.43, 0.0, 0.106], [0, 0, 0])  # beside it, the sphere 2 mm into the top
    assert touched and f == pytest.approx([0, 0, 10.0, 0, 0, 0])
    w.wall = wall_from_params({"point_m": [0, 0, 0.2], "normal": [0, 0, -1], "stiffness_n_m": 1000})
    _, f = wrench(w, [0.43, 0.0, 0.106], [0, 0, 0])  # the wall (above, facing down) not touched: the same
    assert f == pytest.approx([0, 0, 10.0, 0, 0, 0])
    w.change("clear_world", {})
    assert w.empty and wrench(w, [0.43, 0.0, 0.106], [0, 0, 0])[0] is False
    with pytest.raises(ValueError, match="radius_m"):
        w.change("tool", {"radius_m": -1})
