"""The simulated arm in its contact world: a commanded motion into a plane stops at it and the
tool's F/T sensor (`arm.wrench`) reads stiffness × penetration at rest, the joints holding
g(q) − Jᵀ·W; a hole lets the tool through its opening only; clearing the world frees the arm;
a bad shape in the config is refused naming file, key and value. Simulated time (the test's own
ticks), no sleeping."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from orccadd.errors import ConfigError
from orccadd.kinematics import ToolKinematics, damped_pseudo_inverse, pose_error
from orccadd.physres.sim import SimulatedArm
from orccadd.physres.sim_contact import change_world
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.types import CommandMode
from tests.conftest import UR5E

DT = 0.002
STIFF = 50000.0  # N/m


class Arm:
    """A simulated UR5e in position mode, its tool moved along straight lines by commanding the
    joints (inverse kinematics on the command, the tool's orientation kept), one tick at a time
    on the test's clock."""

    def __init__(self, **settings: Any) -> None:
        res = create_resource(with_backend(load_robot_config(UR5E), "sim", **settings))
        assert isinstance(res, SimulatedArm)
        res.configure()
        res.activate(CommandMode.POSITION)
        self.res, self.t = res, 0.0
        self.kin = ToolKinematics(res.model)
        self.q_cmd = res.q.copy()
        self.start = self.kin.pose(self.q_cmd).copy()
        self.target = self.start.translation.copy()

    @property
    def tool_m(self) -> np.ndarray:
        return self.kin.pose(self.res.state.q_rad).translation.copy()

    @property
    def wrench(self) -> np.ndarray:
        return self.res.signals["wrench"]

    def move(self, dp_m: list[float], speed_m_s: float = 0.05, settle_s: float = 1.0) -> np.ndarray:
        """Command the tool `dp_m` further (base axes), then hold; the largest |F| read on the way."""
        start, dp = self.target.copy(), np.asarray(dp_m)
        steps = max(1, int(np.linalg.norm(dp) / speed_m_s / DT))
        peak = 0.0
        for k in range(steps + int(settle_s / DT)):
            self.target = start + dp * min(1.0, (k + 1) / steps)
            for _ in range(2):
                m = self.kin.pose_and_jacobian(self.q_cmd)
                e = pose_error(m.translation, m.rotation, self.target, self.start.rotation)
                self.q_cmd = self.q_cmd + damped_pseudo_inverse(self.kin.jacobian, 1e-3) @ e
            self.res.read(self.t)
            self.res.write(self.t, self.q_cmd)
            self.t += DT
            peak = max(peak, float(np.linalg.norm(self.wrench[:3])))
        return peak


def floor(z_m: float, **law: float) -> dict[str, Any]:
    return {"point_m": [0.0, 0.0, z_m], "normal": [0.0, 0.0, 1.0], "stiffness_n_m": STIFF, **law}


def z0() -> float:
    return float(Arm().start.translation[2])


def test_the_arm_pressed_into_a_plane_stops_at_it_and_feels_stiffness_times_penetration() -> None:
    surface = z0() - 0.02
    free = Arm()
    free.move([0, 0, -0.025])  # without the plane: 5 mm below where the plane will be
    assert abs(free.tool_m[2] - (surface - 0.005)) < 5e-4
    assert free.wrench == pytest.approx(np.zeros(6))
    # no Coulomb friction in the joints: at rest they hold exactly what the contact asks
    arm = Arm(world_planes=[floor(surface)], coulomb_friction_nm=[0.0] * 6)
    arm.move([0, 0, -0.025])
    depth = surface - arm.tool_m[2]
    assert 0.0 < depth < 0.0025, depth  # the plane stopped it: less than half of the 5 mm asked
    fz = arm.wrench[2]
    assert fz == pytest.approx(STIFF * depth, rel=0.02) and fz > 50.0
    assert np.abs(arm.wrench[[0, 1, 3, 4, 5]]).max() < 1e-6  # a frictionless plane: only its normal
    # a second route: the joints' torques at rest are the gravity's minus the contact's Jᵀ·W
    res = arm.res
    assert np.abs(res.state.dq_rad_s).max() < 1e-3
    arm.kin.pose_and_jacobian(res.state.q_rad)
    g = pin.computeGeneralizedGravity(res.model.model, res.model.new_data(), res.state.q_rad)
    expected = g - arm.kin.jacobian.T @ arm.wrench
    assert np.abs(res.state.tau_nm - expected).max() < 0.02 * np.abs(arm.kin.jacobian.T @ arm.wrench).max()


def test_clearing_the_world_frees_the_arm_to_its_commanded_position() -> None:
    surface = z0() - 0.02
    arm = Arm(world_planes=[floor(surface)])
    arm.move([0, 0, -0.025])
    assert arm.wrench[2] > 50.0
    change_world(arm.res.world, "clear_world", {})
    arm.move([0, 0, 0], settle_s=0.5)
    assert arm.wrench == pytest.approx(np.zeros(6))
    assert abs(arm.tool_m[2] - (surface - 0.005)) < 5e-4
    change_world(arm.res.world, "plane", floor(surface - 0.001))  # a plane placed again: felt at once
    arm.move([0, 0, 0], settle_s=0.2)
    assert arm.wrench[2] > 0.0


@pytest.mark.parametrize(("offset_m", "passes"), [(0.0, True), (0.05, False)])
def test_a_tool_above_the_hole_passes_through_it_one_beside_it_does_not(
    offset_m: float, passes: bool
) -> None:
    tool = Arm().start.translation
    surface = tool[2] - 0.02
    hole = {"center_m": [tool[0] + offset_m, tool[1], surface], "normal": [0, 0, 1], "radius_m": 0.01}
    arm = Arm(world_holes=[{**hole, "stiffness_n_m": STIFF}], tool_radius_m=0.004)
    peak = arm.move([0, 0, -0.04])  # 2 cm through the surface
    if passes:
        assert peak == 0.0 and abs(arm.tool_m[2] - (surface - 0.02)) < 5e-4
    else:
        assert arm.wrench[2] > 50.0 and surface - 0.004 - 0.003 < arm.tool_m[2] < surface


def test_in_the_hole_the_tool_pushed_sideways_meets_its_wall() -> None:
    tool = Arm().start.translation
    surface = tool[2] - 0.02
    hole = {"center_m": [tool[0], tool[1], surface], "normal": [0, 0, 1], "radius_m": 0.01, "depth_m": 0.03}
    stiff = 4 * STIFF
    arm = Arm(world_holes=[{**hole, "stiffness_n_m": stiff}], tool_radius_m=0.004)
    arm.move([0, 0, -0.035])  # 1.5 cm down into the hole, on its axis
    assert arm.wrench == pytest.approx(np.zeros(6))
    arm.move([0.01, 0, 0])  # toward +x, 4 mm further than the wall lets a 4 mm sphere go
    radial = arm.tool_m[:2] - tool[:2]
    off_axis = float(np.linalg.norm(radial))
    assert 0.006 < off_axis < 0.006 + 0.002  # stopped at the wall: radius − tool radius + a little
    inward = -radial / off_axis
    assert arm.wrench[:2] == pytest.approx(stiff * (off_axis - 0.006) * inward, rel=0.02, abs=0.5)
    assert arm.wrench[0] < -50.0 and abs(arm.wrench[2]) < 1e-6
    assert arm.tool_m[2] < surface - 0.01  # still in the hole, below its surface


def test_the_sensor_measures_the_wrench_in_the_description_and_its_noise_is_seeded() -> None:
    d = Arm().res.description.as_dict()
    assert any(s.startswith("wrench [6, N|N.m]") and "simulated F/T sensor" in s for s in d["signals"])  # type: ignore[attr-defined]
    readings = []
    for _ in range(2):
        arm = Arm(ft_noise_force_n=0.5, ft_noise_torque_nm=0.01)
        arm.res.read(0.0)
        readings.append(arm.wrench.copy())
    assert readings[0] == pytest.approx(readings[1]) and 0.0 < np.abs(readings[0]).max() < 5.0


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        (
            {"world_planes": [floor(0.3) | {"normal": [0, 0, 0]}]},
            r"robot.toml: resource.settings.world_planes\[0\].normal \(=\[0.0, 0.0, 0.0\]\) must not be zero",
        ),
        (
            {"world_planes": [floor(0.3) | {"stiffness_n_m": -5.0}]},
            r"resource.settings.world_planes\[0\].stiffness_n_m \(=-5.0\) must be in \(0, inf\)",
        ),
        (
            {"world_planes": [floor(0.3) | {"point_m": [0, 0]}]},
            r"world_planes\[0\].point_m \(=\[0.0, 0.0\]\) must be 3 numbers",
        ),
        (
            {"world_holes": [{"center_m": [0, 0, 0], "normal": [0, 0, 1], "stiffness_n_m": 1.0}]},
            r"resource.settings.world_holes\[0\].radius_m is missing",
        ),
        (
            {"world_planes": [floor(0.3) | {"stifness": 1.0}]},
            r"world_planes\[0\].stifness is not a known key",
        ),
    ],
)
def test_a_bad_shape_in_the_config_is_refused_naming_file_key_and_value(
    robot_variant: Any, settings: dict[str, Any], message: str
) -> None:
    cfg = load_robot_config(robot_variant())
    with pytest.raises(ConfigError, match=message):
        with_backend(cfg, "sim", **settings)


def test_a_world_in_the_config_file_is_the_arms_at_start(robot_variant: Any) -> None:
    path = robot_variant(
        (
            "seed = 1\n",
            "seed = 1\ntool_radius_m = 0.004\n"
            "world_planes = [{point_m = [0, 0, 0.1], normal = [0, 0, 1], stiffness_n_m = 5000, "
            "friction = 0.3}]\n"
            "world_holes = [{center_m = [0.5, 0, 0.1], normal = [0, 0, 1], radius_m = 0.01, "
            "stiffness_n_m = 5000}]\n",
        )
    )
    res = create_resource(load_robot_config(path))
    assert isinstance(res, SimulatedArm)
    world = res.world.describe()
    assert world["tool_radius_m"] == 0.004
    assert [(s["shape"], s["friction"]) for s in world["shapes"]] == [("plane", 0.3), ("hole", 0.0)]
