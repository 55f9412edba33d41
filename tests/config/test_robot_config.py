"""Robot configs: the shipped ones load; bad ones are refused naming file, key, value, range."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.config.robot import read_robot_config
from orccadd.errors import ConfigError
from orccadd.robot import load_robot_config
from tests.conftest import PANDA, UR5E


def test_shipped_configs_load() -> None:
    ur = load_robot_config(UR5E)
    assert ur.dof == 6 and ur.resource.backend == "sim"
    panda = load_robot_config(PANDA)
    assert panda.dof == 7
    assert panda.joint_names[0] == "panda_joint1"


BAD = [
    # (edit, substring the message must contain)
    (
        ("max_velocity_rad_s = 3.1415\n", "max_velocity_rad_s = 12.0\n"),
        "joints[0].max_velocity_rad_s (=12.0) must be in (0, 3.14159] (URDF limit of shoulder_pan_joint)",
    ),
    (
        ("max_torque_nm = 28.0\n", "max_torque_nm = 40.0\n"),
        "joints[3].max_torque_nm (=40.0) must be in (0, 28] (URDF limit of wrist_1_joint)",
    ),
    (
        ("max_jerk_rad_s3 = 60.0\n", "max_jerk_rad_s3 = -1.0\n"),
        "joints[0].max_jerk_rad_s3 (=-1.0) must be in (0, inf]",
    ),
    (
        ('name = "ur5e"', 'name = "ur5e"\ncolour = "blue"'),
        "colour is not a known key (allowed here:",
    ),
    (
        ("control_period_s = 0.002", "control_period_s = 0.5"),
        "control_period_s (=0.5) must be in [0.0001, 0.1]",
    ),
    (
        ("control_period_s = 0.002", 'control_period_s = "fast"'),
        "control_period_s (='fast') must be a number",
    ),
    (('backend = "sim"', 'backend = "ethercat"'), "resource.backend (='ethercat') must be one of"),
    (
        ('name = "elbow_joint"', 'name = "elbow"'),
        "joints[2].name (='elbow') is not a joint of ur5e.urdf",
    ),
    (
        ('name = "elbow_joint"', 'name = "wrist_1_joint"'),
        "joints[3].name (='wrist_1_joint') is listed twice",
    ),
    (("category = 1", "category = 3"), "safe_stop.category (=3) must be one of 0, 1, 2"),
    (("seed = 1", "seed = 1\nsubstep = 0.001"), "resource.settings.substep is not a known key"),
    (
        ("substep_s = 0.0005", "substep_s = 0.01"),
        "resource.settings.substep_s (=0.01) must be at most control_period_s (=0.002)",
    ),
    (
        (
            "coulomb_friction_nm = [4.0, 4.0, 3.0, 1.0, 1.0, 1.0]",
            "coulomb_friction_nm = [4.0, 4.0]",
        ),
        "resource.settings.coulomb_friction_nm has 2 entries, must have one per joint (6) or none",
    ),
    (
        ("home_rad = 1.5708", "home_rad = 4.0"),
        "joints[2].home_rad (=4.0) must be in [-3.1415, 3.1415]",
    ),
    (
        ("position_max_rad = 3.1415", "position_max_rad = 3.2"),
        "joints[2].position_max_rad (=3.2) must be in [-3.14159, 3.14159] (URDF limit of elbow_joint)",
    ),
    (('urdf = "', 'urdf = "missing/'), "model.urdf (="),
    (
        ("armature_kg_m2 = [0.4, 0.4, 0.4, 0.1, 0.1, 0.1]", "armature_kg_m2 = [0.4]"),
        "model.armature_kg_m2 has 1 entries, must have one per joint (6) or none",
    ),
    (
        (
            "initial_q_rad = [0.3, -1.2, 1.0, -1.2, -1.4, 0.2]",
            "initial_q_rad = [0.3, -1.2, 5.0, -1.2, -1.4, 0.2]",
        ),
        "resource.settings.initial_q_rad[2] (=5.0) must be in [-3.1415, 3.1415] (elbow_joint)",
    ),
    (
        ('frame = "tool0"', 'frame = "gripper_tip"'),
        "tool.frame (='gripper_tip') is not a frame of ur5e.urdf (frames: base_link, ",
    ),
    (
        ('frame = "tool0"', 'frame = "base_link"'),
        "tool.frame (='base_link') is fixed to the base: no joint moves it, so no task can",
    ),
    (
        ('frame = "tool0"', 'frame = "tool0"\noffset_m = [0.0, 0.1]'),
        "tool.offset_m has 2 entries, must have 3 numbers (x, y, z)",
    ),
    (
        ('frame = "tool0"', 'frame = "tool0"\nmax_linear_velocity_m_s = 0.0'),
        "tool.max_linear_velocity_m_s (=0.0) must be in (0, 5]",
    ),
    (
        ("[safe_stop]", "[workspace]\nbox_min_m = [-1.0, -1.0, 0.0]\n\n[safe_stop]"),
        "workspace.box_max_m is missing: a box needs both corners (box_min_m is given)",
    ),
    (
        (
            "[safe_stop]",
            "[workspace]\nbox_min_m = [-1.0, -1.0, 0.0]\nbox_max_m = [1.0, 1.0, 0.0]\n\n[safe_stop]",
        ),
        "workspace.box_max_m (=[1.0, 1.0, 0.0]) must exceed box_min_m at index 2",
    ),
    (
        ("[safe_stop]", "[workspace]\nsphere_center_m = [0.0, 0.0, 0.3]\n\n[safe_stop]"),
        "workspace.sphere_radius_m (=0.0): a sphere needs both sphere_center_m and a radius > 0",
    ),
]


@pytest.mark.parametrize(("edit", "message"), BAD, ids=[m.split(" ")[0] for _, m in BAD])
def test_bad_config_is_refused_with_specific_message(robot_variant, edit, message) -> None:  # type: ignore[no-untyped-def]
    path = robot_variant(edit)
    with pytest.raises(ConfigError) as exc:
        load_robot_config(path)
    text = str(exc.value)
    assert text.startswith(str(path)), text
    assert message in text, text


def test_syntax_error_names_file_and_line(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "broken.toml"
    p.write_text('name = "x"\ncontrol_period_s = = 0.001\n')
    with pytest.raises(ConfigError, match=r"broken.toml: is not valid TOML: .*line 2"):
        load_robot_config(p)


def test_missing_key_says_what_is_needed(robot_variant) -> None:  # type: ignore[no-untyped-def]
    path = robot_variant(("max_torque_nm = 150.0\n", ""))
    with pytest.raises(ConfigError, match=r"joints\[0\].max_torque_nm is missing \(a number needed\)"):
        load_robot_config(path)


def test_unlisted_urdf_joint_must_be_locked(robot_variant) -> None:  # type: ignore[no-untyped-def]
    path = robot_variant(
        ('locked_joints = ["panda_finger_joint1", "panda_finger_joint2"]', "locked_joints = []"),
        ("locked_positions = [0.02, 0.02]", ""),
        base=PANDA,
    )
    with pytest.raises(ConfigError, match="does not list panda_finger_joint1, panda_finger_joint2"):
        load_robot_config(path)


@pytest.mark.parametrize(
    ("content", "why"),
    [
        (b"\xff\xfe\x00binary\x80", "is not UTF-8 text, so not TOML"),
        (b"name = [unclosed", "is not valid TOML"),
        (None, "cannot be read"),  # a directory
        (b"a = " + b"[" * 100_000 + b"]" * 100_000, "nests arrays or tables too deeply"),
        (b"# " + b"x" * (2 << 20), "is larger than 1048576 bytes"),
    ],
)
def test_an_unreadable_config_is_a_config_error_naming_the_file(
    tmp_path: Path, content: bytes | None, why: str
) -> None:
    path = tmp_path / "robot.toml"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    with pytest.raises(ConfigError, match=why) as info:
        read_robot_config(path)
    assert str(path) in str(info.value)
