"""The UR controller's state words, read as the backend reads them every tick."""

from __future__ import annotations

import pytest

from orccadd.drivers.ur.controller import (
    RobotMode,
    RuntimeState,
    SafetyMode,
    condition,
    parse_polyscope_version,
    robot_model_name,
    safety_bits_text,
)

RUNNING, NORMAL, PLAYING = RobotMode.RUNNING, SafetyMode.NORMAL, RuntimeState.PLAYING


def test_a_running_arm_in_normal_or_reduced_mode_with_its_script_may_move() -> None:
    assert condition(RUNNING, NORMAL, PLAYING, True) is None
    assert condition(RUNNING, SafetyMode.REDUCED, PLAYING, True) is None


@pytest.mark.parametrize(
    ("safety", "unlockable", "needs"),
    [
        (SafetyMode.PROTECTIVE_STOP, True, ""),
        (SafetyMode.SAFEGUARD_STOP, False, "clears when the safeguard input is reset"),
        (SafetyMode.ROBOT_EMERGENCY_STOP, False, "pendant: release the emergency stop button"),
        (SafetyMode.SYSTEM_EMERGENCY_STOP, False, "pendant: release the emergency stop button"),
        (SafetyMode.VIOLATION, False, "pendant: restart the safety system"),
        (SafetyMode.FAULT, False, "pendant: restart the safety system"),
    ],
)
def test_each_safety_stop_is_named_with_how_it_is_recovered(
    safety: SafetyMode, unlockable: bool, needs: str
) -> None:
    c = condition(RUNNING, safety, PLAYING, True)
    assert c is not None and c.what == f"safety mode {safety.name}"
    assert (c.unlockable, c.needs) == (unlockable, needs)


def test_power_off_and_a_stopped_script_are_conditions_too() -> None:
    off = condition(RobotMode.POWER_OFF, NORMAL, PLAYING, False)
    assert off is not None and off.what == "robot mode POWER_OFF" and "power on" in off.needs
    script = condition(RUNNING, NORMAL, RuntimeState.STOPPED, False)
    assert script is not None and "control script is not running (program STOPPED)" in script.what
    assert script.needs == ""  # `reset` restarts it
    odd = condition(RUNNING, 99, PLAYING, True)
    assert odd is not None and odd.what == "safety mode #99" and odd.needs == "pendant"


def test_versions_models_and_bits() -> None:
    v = parse_polyscope_version("URSoftware 5.11.1.108318 (Jan 14 2022)")
    assert (v.major, v.minor, v.bugfix, v.build) == (5, 11, 1, 108318) and v.e_series
    assert v.period_s == 0.002
    cb3 = parse_polyscope_version("URSoftware 3.15.7.106331 (Aug 17 2021)")
    assert not cb3.e_series and cb3.period_s == 0.008
    assert robot_model_name("UR5\n", v) == "UR5e" and robot_model_name("UR5", cb3) == "UR5"
    assert robot_model_name("UR20", v) == "UR20"
    with pytest.raises(ValueError):
        parse_polyscope_version("Connected: Universal Robots Dashboard Server")
    assert safety_bits_text(0b101) == "normal, protective stopped" and safety_bits_text(0) == "none"
