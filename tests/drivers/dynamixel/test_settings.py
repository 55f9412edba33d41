"""The strict `[resource.settings]` loader and the config-time refusals of the description:
each error names the file, the key, the value and what was allowed."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel.models import CURRENT, EXTENDED_POSITION, POSITION, VELOCITY
from orccadd.drivers.dynamixel.startup import eeprom_targets, operating_modes
from orccadd.errors import ConfigError
from orccadd.physres.dynamixel import DynamixelArm
from orccadd.robot import load_robot_config
from orccadd.types import CommandMode
from tests.conftest import ROOT, variant_text

SIM = ROOT / "configs/robots/dxl-6axis-sim.toml"
REAL = ROOT / "configs/robots/dxl-6axis.toml"
SERVO1 = 'id = 1\nmodel = "XM540-W270"\ndirection = 1\noffset_rad = 0.0\ngear_ratio = 1.0\noperating_mode = "position"'  # noqa: E501
SERVO4 = SERVO1.replace("id = 1", "id = 4").replace("XM540-W270", "XM430-W350")


def variant(tmp_path: Path, *edits: tuple[str, str]) -> Path:
    p = tmp_path / "dxl.toml"
    p.write_text(variant_text(SIM, *edits))
    return p


def refused(tmp_path: Path, *edits: tuple[str, str]) -> str:
    with pytest.raises(ConfigError) as e:
        load_robot_config(variant(tmp_path, *edits))
    return str(e.value)


def test_the_shipped_configs_load_and_describe_the_chain() -> None:
    for path in (SIM, REAL):
        cfg = load_robot_config(path)
        s = cfg.backend_settings
        assert s.baud_rate == 4_000_000 and [v.id for v in s.servos] == [1, 2, 3, 4, 5, 6]
        d = DynamixelArm.describe(cfg)
        assert d.modes == {CommandMode.POSITION, CommandMode.VELOCITY, CommandMode.TORQUE}
        assert d.mode_switch_needs_disable and not d.brakes
        assert d.stop_categories == {0, 2}  # 1 only where torque off at rest is declared safe
        assert d.read_time_s == pytest.approx(112 * 10 / 4e6)
        assert d.write_time_s == pytest.approx(44 * 10 / 4e6)


def test_a_rate_the_servos_do_not_have(tmp_path: Path) -> None:
    msg = refused(tmp_path, ("baud_rate = 4_000_000", "baud_rate = 1_500_000"))
    assert "dxl.toml: resource.settings.baud_rate (=1500000) must be one of 57600, 115200" in msg
    msg = refused(tmp_path, ("baud_rate = 4_000_000", "baud_rate = 4_500_000"))
    assert "resource.settings.baud_rate (=4500000) must be in [57600, 4e+06]" in msg


def test_one_servo_per_joint_each_id_once(tmp_path: Path) -> None:
    msg = refused(tmp_path, (f"[[resource.settings.servos]]\n{SERVO1}\n", ""))
    assert "resource.settings.servos has 5 entries, must have one per joint (6)" in msg
    msg = refused(tmp_path, ('id = 2\nmodel = "XM540-W270"', 'id = 1\nmodel = "XM540-W270"'))
    assert "resource.settings.servos[1].id (=1) is used twice" in msg


def test_models_and_their_modes(tmp_path: Path) -> None:
    msg = refused(tmp_path, ('id = 4\nmodel = "XM430-W350"', 'id = 4\nmodel = "AX-12A"'))
    assert "resource.settings.servos[3].model (='AX-12A') must be one of 'XM430-W350'" in msg
    xl = (SERVO4, SERVO4.replace("XM430-W350", "XL430-W250").replace('"position"', '"current"'))
    msg = refused(tmp_path, xl)
    assert "servos[3].operating_mode (='current') is not a mode of the XL430-W250 (servo 4)" in msg
    msg = refused(tmp_path, (SERVO1, SERVO1.replace('"position"', '"pwm"')))
    assert "servos[0].operating_mode (='pwm') must be one of 'position'" in msg
    cfg = load_robot_config(variant(tmp_path, (xl[0], xl[1].replace('"current"', '"velocity"'))))
    assert CommandMode.TORQUE not in DynamixelArm.describe(cfg).modes  # the XL430 measures no current


def test_position_mode_must_reach_the_joint_range_within_one_turn(tmp_path: Path) -> None:
    msg = refused(tmp_path, (SERVO1, SERVO1.replace("offset_rad = 0.0", "offset_rad = 1.0")))
    assert "servos[0].operating_mode (='position') cannot reach joint waist's range [-3.1, 3.1] rad" in msg
    assert "use 'extended_position' or move offset_rad" in msg
    extended = SERVO1.replace("offset_rad = 0.0", "offset_rad = 1.0").replace(
        '"position"', '"extended_position"'
    )
    cfg = load_robot_config(variant(tmp_path, (SERVO1, extended)))
    assert operating_modes(cfg.backend_settings, cfg, CommandMode.POSITION)[0] == EXTENDED_POSITION


def test_category_1_needs_torque_off_at_rest_declared_safe(tmp_path: Path) -> None:
    msg = refused(tmp_path, ("category = 2", "category = 1"))
    assert "safe_stop.category (=1) ends with the servos' torque off" in msg
    assert "resource.settings.torque_off_at_rest = true" in msg
    cfg = load_robot_config(
        variant(
            tmp_path,
            ("category = 2", "category = 1"),
            ("baud_rate = 4_000_000", "baud_rate = 4_000_000\ntorque_off_at_rest = true"),
        )
    )
    assert 1 in DynamixelArm.describe(cfg).stop_categories


def test_category_0_drops_a_gravity_loaded_arm(tmp_path: Path) -> None:
    msg = refused(tmp_path, ("category = 2", "category = 0"))
    assert "safe_stop.category (=0) would drop the arm: the dynamixel resource has no brakes" in msg


def test_a_period_shorter_than_the_chains_wire_time_is_refused(tmp_path: Path) -> None:
    # six servos at 57,600 bit/s: (20 + 92 + 44) bytes = 27 ms of wire for a 5 ms period
    msg = refused(tmp_path, ("baud_rate = 4_000_000", "baud_rate = 57_600"))
    assert "control_period_s (=0.005) must be at least the dynamixel resource's read + write time" in msg
    assert "(0.0194444 + 0.00763889 s)" in msg
    ok = load_robot_config(
        variant(
            tmp_path,
            ("baud_rate = 4_000_000", "baud_rate = 57_600"),
            ("control_period_s = 0.005", "control_period_s = 0.04"),
        )
    )
    assert ok.backend_settings.baud_rate == 57_600


def test_the_read_timeout_must_fit_in_the_period(tmp_path: Path) -> None:
    msg = refused(tmp_path, ("baud_rate = 4_000_000", "baud_rate = 4_000_000\nread_timeout_s = 0.0049"))
    assert "resource.settings.read_timeout_s (=0.0049) plus the chain's read + write time" in msg


def test_unknown_keys_are_refused(tmp_path: Path) -> None:
    msg = refused(tmp_path, ("baud_rate = 4_000_000", "baud_rate = 4_000_000\nbaudrate = 1"))
    assert "resource.settings.baudrate is not a known key (allowed here:" in msg


def test_eeprom_targets_and_operating_modes_from_the_config() -> None:
    cfg = load_robot_config(SIM)
    s = cfg.backend_settings
    targets = eeprom_targets(s, cfg)
    waist = targets[0].values
    assert waist[T.RETURN_DELAY_TIME] == 0 and waist[T.OPERATING_MODE] == POSITION
    assert (waist[T.MIN_POSITION_LIMIT], waist[T.MAX_POSITION_LIMIT]) == (27, 4069)  # +-3.1 rad
    assert waist[T.VELOCITY_LIMIT] == 115  # 2.5 rad/s x 1.1 in 0.229 rpm units, rounded up
    assert waist[T.CURRENT_LIMIT] == 1636  # 10.6 N.m through 2.409 N.m/A in 2.69 mA units
    assert operating_modes(s, cfg, CommandMode.VELOCITY) == [VELOCITY] * 6
    assert operating_modes(s, cfg, CommandMode.TORQUE) == [CURRENT] * 6
    assert operating_modes(s, cfg, CommandMode.POSITION) == [POSITION] * 6
    block = bytearray(64)
    for item, v in waist.items():
        block[item.address : item.address + item.size] = bytes(item.encode(v))
    assert targets[0].differences(bytes(block)) == {}
    block[T.DRIVE_MODE.address] = 0x03  # reversed (bit 0) + dual joint (bit 1): bit 1 stays
    block[T.RETURN_DELAY_TIME.address] = 250
    assert targets[0].differences(bytes(block)) == {T.DRIVE_MODE: 0x02, T.RETURN_DELAY_TIME: 0}
