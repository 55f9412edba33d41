"""The simulated arm's camera (`sim`, and `sim_process` through its plant): at home (the tool
pointing down, its x along the base's y and its y along the base's x) a target's points project
where a hand computation puts them; a point out of the image, behind the camera, or an occluder
hides the target (its features keep their last values) until it is seen again; the pixel noise
is seeded and of the configured std; the signals are declared only with a camera; bad settings
are refused naming file, key and value."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from orccadd.errors import ConfigError
from orccadd.kinematics import ToolKinematics
from orccadd.physres.sim import SimulatedArm
from orccadd.physres.sim_camera import SimCamera, change_camera
from orccadd.physres.sim_process import SimProcessArm
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.runtime import WallClock
from orccadd.session import Session
from orccadd.simctl import main as simctl
from orccadd.simproc import control_request
from tests.conftest import ROOT, UR5E

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
FOCAL_PX, WIDTH_PX, HEIGHT_PX = 600.0, 640, 480
DEPTH_M = 0.3
# (base dx, base dy) of each point from the tool at home, DEPTH_M below it: a 6 cm square, off-centre
OFFSETS = [(-0.01, -0.04), (-0.01, 0.02), (0.05, 0.02), (0.05, -0.04)]


def tool_at_home() -> np.ndarray:
    model = create_resource(load_robot_config(UR5E)).model
    return ToolKinematics(model).pose(np.array(HOME)).translation.copy()


TOOL = tool_at_home()


def points(offsets: list[tuple[float, float]] = OFFSETS, depth_m: float = DEPTH_M) -> list[list[float]]:
    return [[float(TOOL[0] + dx), float(TOOL[1] + dy), float(TOOL[2] - depth_m)] for dx, dy in offsets]


def arm(**camera: Any) -> SimulatedArm:
    """A simulated UR5e at home, brakes on (it stays there), its camera set by `camera`."""
    settings = {"target_points_m": points(), "focal_px": FOCAL_PX, "image_size_px": [WIDTH_PX, HEIGHT_PX]}
    cfg = with_backend(load_robot_config(UR5E), "sim", initial_q_rad=HOME, camera={**settings, **camera})
    res = create_resource(cfg)
    assert isinstance(res, SimulatedArm)
    res.configure()
    return res


def seen(res: SimulatedArm, t_s: float = 0.0) -> tuple[np.ndarray, float]:
    res.read(t_s)
    return res.signals["features"].copy(), float(res.signals["target_visible"][0])


def camera(res: SimulatedArm) -> SimCamera:
    assert res.camera is not None
    return res.camera


def by_hand(offsets: list[tuple[float, float]] = OFFSETS, depth_m: float = DEPTH_M) -> np.ndarray:
    """At home the camera's x is the base's y, its y the base's x, its z the base's -z: a point
    (dx, dy) off the tool and depth_m below it is at (X, Y, Z) = (dy, dx, depth_m)."""
    return np.array([[dy / depth_m, dx / depth_m] for dx, dy in offsets]).ravel()


def test_the_points_project_where_a_hand_computation_puts_them() -> None:
    features, visible = seen(arm())
    assert visible == 1.0
    assert features == pytest.approx(by_hand(), abs=1e-4)
    # the camera 5 cm ahead of the tool along its axis: the same points 5 cm nearer
    nearer, _ = seen(arm(offset_m=[0.0, 0.0, 0.05]))
    assert nearer == pytest.approx(by_hand(depth_m=DEPTH_M - 0.05), abs=1e-4)


def test_a_point_out_of_the_image_hides_the_target_and_the_features_keep_their_last_values() -> None:
    res = arm()
    first, _ = seen(res)
    # the image's half-width is 320 px / 600 px = 0.533 in x (the base's y): 0.6 is out of it
    out = [*OFFSETS[:3], (0.0, 0.6 * DEPTH_M)]
    change_camera(res.camera, "target", {"points_m": points(out)})
    features, visible = seen(res)
    assert visible == 0.0 and features == pytest.approx(first)
    # just inside the image: seen
    change_camera(res.camera, "target", {"points_m": points([*OFFSETS[:3], (0.0, 0.5 * DEPTH_M)])})
    features, visible = seen(res)
    assert visible == 1.0 and features[6] == pytest.approx(0.5, abs=1e-4)
    # in y (the base's x), half-height 240 / 600 = 0.4
    change_camera(res.camera, "target", {"points_m": points([*OFFSETS[:3], (0.42 * DEPTH_M, 0.0)])})
    assert seen(res)[1] == 0.0


def test_a_target_behind_the_camera_is_not_seen() -> None:
    res = arm(target_points_m=points(depth_m=-DEPTH_M))  # above the tool pointing down
    features, visible = seen(res)
    assert visible == 0.0 and not features.any()  # never seen: the features are still zeros
    # one point only behind: not seen either
    behind = points()
    behind[2][2] = TOOL[2] + 0.1
    change_camera(res.camera, "target", {"points_m": behind})
    assert seen(res)[1] == 0.0


def test_an_occluder_hides_the_target_until_it_is_taken_away() -> None:
    res = arm()
    first, visible = seen(res)
    assert visible == 1.0
    change_camera(res.camera, "occlude", {})
    features, visible = seen(res)
    assert visible == 0.0 and features == pytest.approx(first) and camera(res).describe()["occluded"]
    change_camera(res.camera, "unocclude", {})
    features, visible = seen(res)
    assert visible == 1.0 and features == pytest.approx(first)


def test_without_a_target_nothing_is_seen_until_one_is_set() -> None:
    res = arm(target_points_m=[])
    assert seen(res) == (pytest.approx(np.zeros(8)), 0.0)
    change_camera(res.camera, "target", {"points_m": points()})
    features, visible = seen(res)
    assert visible == 1.0 and features == pytest.approx(by_hand(), abs=1e-4)


def test_the_pixel_noise_is_seeded_and_of_the_configured_std() -> None:
    noise_px = 2.0
    runs = []
    for seed_arm in (arm(noise_px=noise_px), arm(noise_px=noise_px)):
        runs.append(np.array([seen(seed_arm)[0] for _ in range(3000)]))  # t stays 0: the arm still
    assert np.array_equal(runs[0], runs[1])  # the same seed, the same noise
    errors = (runs[0] - by_hand()) * FOCAL_PX  # in pixels (the hand's rounding is < 0.1 px)
    assert errors.std() == pytest.approx(noise_px, rel=0.05)
    assert abs(errors.mean()) < 0.05 * noise_px
    other = with_backend(arm().config, "sim", seed=2)
    res = create_resource(other)
    assert isinstance(res, SimulatedArm)
    res.configure()
    change_camera(res.camera, "target", {"points_m": points()})
    assert seen(res)[0] == pytest.approx(by_hand(), abs=1e-4)  # no noise configured: none


def test_the_signals_are_declared_with_a_camera_only() -> None:
    names = [s.split(" ")[0] for s in arm().description.as_dict()["signals"]]  # type: ignore[attr-defined]
    assert names == ["wrench", "features", "target_visible"]
    cfg = load_robot_config(UR5E)
    for settings in ({}, {"camera": {"enabled": False, "target_points_m": points()}}):
        res = create_resource(with_backend(cfg, "sim", **settings))
        assert [s.name for s in res.description.signals] == ["wrench"] and res.camera is None  # type: ignore[attr-defined]


def test_a_camera_in_the_config_file(robot_variant: Any) -> None:
    table = "\n".join(
        [
            "seed = 1",
            "",
            "[resource.settings.camera]",
            f"target_points_m = {points()}",
            "focal_px = 500.0",
            "image_size_px = [800, 600]",
            "noise_px = 0.5",
            "",
        ]
    )
    res = create_resource(load_robot_config(robot_variant(("seed = 1\n", table + "\n"))))
    assert isinstance(res, SimulatedArm) and res.camera is not None
    d = res.camera.describe()
    assert d["focal_px"] == 500.0 and d["image_size_px"] == [800, 600] and d["target_points_m"] == points()


@pytest.mark.parametrize(
    ("camera", "message"),
    [
        (
            {"target_points_m": points()[:3]},
            r"robot.toml: resource.settings.camera.target_points_m \(=\[\[.*\]\]\) "
            r"must be 4 points \[x, y, z\] \(m, base frame\)",
        ),
        (
            {"target_points_m": [*points()[:3], [0.1, 0.2]]},
            r"resource.settings.camera.target_points_m \(=.*\[0.1, 0.2\]\]\) must be 4 points",
        ),
        (
            {"target_points_m": [*points()[:3], points()[0]]},
            r"camera.target_points_m \(=.*\) must be distinct points: \[0\] and \[3\] are the same",
        ),
        (
            {"target_points_m": [*points()[:3], [0.0, 0.0, 30.0]]},
            r"resource.settings.camera.target_points_m\[3\]\[2\] \(=30.0\) must be in \[-20, 20\]",
        ),
        ({"focal_px": 0.0}, r"resource.settings.camera.focal_px \(=0.0\) must be in \[1, 100000\]"),
        (
            {"image_size_px": [640]},
            r"resource.settings.camera.image_size_px \(=\[640\]\) must have 2 entries",
        ),
        ({"image_size_px": [640, 0]}, r"camera.image_size_px\[1\] \(=0\) must be in \[1, 100000\]"),
        ({"noise_px": -1.0}, r"resource.settings.camera.noise_px \(=-1.0\) must be in \[0, 100\]"),
        ({"offset_m": [0.0, 0.05]}, r"camera.offset_m \(=\[0.0, 0.05\]\) must have 3 entries"),
        ({"fov_rad": 0.5}, r"resource.settings.camera.fov_rad is not a known key \(allowed here: enabled, "),
    ],
)
def test_bad_camera_settings_are_refused_naming_file_key_and_value(
    robot_variant: Any, camera: dict[str, Any], message: str
) -> None:
    cfg = load_robot_config(robot_variant())
    with pytest.raises(ConfigError, match=message):
        with_backend(cfg, "sim", camera=camera)


@pytest.mark.parametrize(
    ("what", "params", "message"),
    [
        ("target", {}, r'target: "points_m" is required \(4 points \[x, y, z\]\)'),
        ("target", {"points_m": [[0, 0, 0]]}, r'target: "points_m" \(=\[\[0, 0, 0\]\]\) must be 4 points'),
        ("occlude", {"on": True}, r"occlude: unknown parameter\(s\) on"),
    ],
)
def test_a_bad_change_of_the_scene_is_refused_and_changes_nothing(
    what: str, params: dict[str, Any], message: str
) -> None:
    res = arm()
    with pytest.raises(ValueError, match=message):
        change_camera(res.camera, what, params)
    assert seen(res)[1] == 1.0


def test_an_arm_without_a_camera_refuses_a_change_of_its_scene() -> None:
    res = create_resource(load_robot_config(UR5E))
    assert isinstance(res, SimulatedArm)
    with pytest.raises(ValueError, match=r"occlude: the arm has no camera"):
        change_camera(res.camera, "occlude", {})


def test_over_sim_process_the_plant_measures_and_its_control_channel_occludes() -> None:
    """The plant in its own process carries the camera's signals over the shared memory; its
    control channel (the resource's `plant_control`) occludes the target and moves it."""
    settings = {"target_points_m": points(), "focal_px": FOCAL_PX, "image_size_px": [WIDTH_PX, HEIGHT_PX]}
    cfg = with_backend(load_robot_config(UR5E), "sim_process", initial_q_rad=HOME, camera=settings)
    s = Session.from_config(cfg)
    try:
        res = s.resource
        assert isinstance(res, SimProcessArm)
        address = res.plant_control
        loop = s.loop(WallClock(), overrun_limit=10**6)
        loop.active = s.task(ROOT / "configs/tasks/hold.toml")
        loop.active.activate()
        loop.run_for(0.1)
        first = res.signals["features"].copy()
        assert res.signals["target_visible"][0] == 1.0 and first == pytest.approx(by_hand(), abs=2e-3)
        assert simctl([address, "inject", "occlude"]) == 0
        loop.run_for(0.05)
        assert res.signals["target_visible"][0] == 0.0
        assert simctl([address, "inject", "unocclude"]) == 0
        moved = [(dx + 0.01, dy) for dx, dy in OFFSETS]  # 1 cm along the base's x: the image's y
        assert simctl([address, "inject", "target", f"points_m={json.dumps(points(moved))}"]) == 0
        loop.run_for(0.05)
        assert res.signals["target_visible"][0] == 1.0
        assert res.signals["features"] == pytest.approx(by_hand(moved), abs=2e-3)
        status = control_request(address, {"status": True})
        assert status["camera"]["target_visible"] and status["camera"]["target_points_m"] == points(moved)
    finally:
        s.close()
