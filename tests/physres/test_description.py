"""What a resource declares, and the configs its declaration rules out before anything moves."""

from __future__ import annotations

from dataclasses import replace

import pytest

from orccadd.errors import ConfigError
from orccadd.model import RobotModel
from orccadd.physres.description import (
    ABSENT,
    MEASURED,
    ClockSource,
    Quantity,
    ResourceDescription,
    Source,
    check_description,
)
from orccadd.physres.sim import SimulatedArm
from orccadd.robot import load_robot_config
from orccadd.types import CommandMode
from tests.conftest import UR5E


@pytest.fixture(scope="module")
def cfg():  # type: ignore[no-untyped-def]
    return load_robot_config(UR5E)


def servo_chain(cfg) -> ResourceDescription:  # type: ignore[no-untyped-def]
    """Like a Dynamixel chain: no brakes, torque estimated, a read that takes wire time."""
    return ResourceDescription(
        backend="chain",
        joints=cfg.joint_names,
        modes=frozenset({CommandMode.POSITION}),
        mode_switch_needs_disable=True,
        position=MEASURED,
        velocity=MEASURED,
        torque=Quantity(Source.ESTIMATED, "motor current"),
        brakes=False,
        stop_categories=frozenset({0, 1, 2}),
        read_time_s=0.0015,
        write_time_s=0.0006,
    )


def test_a_period_shorter_than_read_plus_write_is_refused(cfg) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(
        ConfigError, match=r"control_period_s \(=0.002\) must be at least .* \(0.0015 \+ 0.0006 s\)"
    ):
        check_description(cfg, servo_chain(cfg), gravity_loaded=False)
    check_description(replace(cfg, control_period_s=0.004), servo_chain(cfg), gravity_loaded=False)


def test_category_0_without_brakes_is_refused_on_a_gravity_loaded_arm_only(cfg) -> None:  # type: ignore[no-untyped-def]
    cat0 = replace(cfg, control_period_s=0.004, safe_stop=replace(cfg.safe_stop, category=0))
    with pytest.raises(ConfigError, match=r"safe_stop.category \(=0\) would drop the arm: .* no brakes"):
        check_description(cat0, servo_chain(cfg), gravity_loaded=True)
    check_description(cat0, servo_chain(cfg), gravity_loaded=False)  # e.g. a horizontal SCARA
    check_description(cat0, replace(servo_chain(cfg), brakes=True), gravity_loaded=True)


def test_a_stop_category_the_device_cannot_do_is_refused(cfg) -> None:  # type: ignore[no-untyped-def]
    d = replace(servo_chain(cfg), read_time_s=0.0, write_time_s=0.0, stop_categories=frozenset({2}))
    with pytest.raises(ConfigError, match=r"safe_stop.category \(=1\) must be one of 2"):
        check_description(cfg, d, gravity_loaded=True)


def test_a_device_paced_resource_needs_the_devices_period(cfg) -> None:  # type: ignore[no-untyped-def]
    cb3 = replace(servo_chain(cfg), read_time_s=0.0, write_time_s=0.0, brakes=True)
    cb3 = replace(cb3, clock=ClockSource.DEVICE, device_period_s=0.008)  # a CB3 controller: 125 Hz
    with pytest.raises(
        ConfigError, match=r"control_period_s \(=0.002\) must equal the device's cycle \(0.008 s\)"
    ):
        check_description(cfg, cb3, gravity_loaded=True)
    check_description(replace(cfg, control_period_s=0.008), cb3, gravity_loaded=True)


def test_the_ur5e_is_loaded_by_gravity() -> None:
    model = RobotModel.from_config(load_robot_config(UR5E))
    assert model.gravity_loaded()


def test_loading_a_config_applies_the_checks(robot_variant) -> None:  # type: ignore[no-untyped-def]
    path = robot_variant(("control_period_s = 0.002", "control_period_s = 0.002"))
    load_robot_config(path)  # the simulated arm: brakes, every category, no bus time
    d = SimulatedArm.describe(load_robot_config(path))
    assert d.brakes and d.stop_categories == {0, 1, 2} and d.torque.source is Source.MEASURED
    assert d.as_dict()["torque"] == "measured"
    assert ABSENT.describe() == "absent"


def test_a_backend_whose_bus_package_is_missing_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import orccadd.physres as physres

    monkeypatch.setitem(physres.EXTRAS, "ur_rtde", ("ur", ("no_such_rtde_package",)))
    needs = r"needs the Python package\(s\) no_such_rtde_package.*orccadd\[ur\]"
    with pytest.raises(ConfigError, match=needs):
        physres.backend_class("ur_rtde", "robot.toml")
