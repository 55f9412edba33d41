"""Joint units from and to servo units: the config's formula, exact inverses, limits in ticks."""

from __future__ import annotations

import math

import pytest

from orccadd.drivers.dynamixel.models import MODELS
from orccadd.drivers.dynamixel.units import CENTER_TICKS, JointUnits

XM430 = MODELS["XM430-W350"]


def test_the_configs_joint_angle_formula() -> None:
    # q_rad = offset_rad + direction * (Present Position - 2048) * 2*pi / 4096 / gear_ratio
    for direction in (1, -1):
        for gear in (1.0, 2.5):
            u = JointUnits(direction, gear, 0.3, XM430)
            for ticks in (0, 1000, 2048, 3000, 4095, 10_000):
                expected = 0.3 + direction * (ticks - 2048) * 2 * math.pi / 4096 / gear
                assert u.q_rad(ticks) == pytest.approx(expected)
                assert u.ticks(u.q_rad(ticks)) == ticks  # the inverse, exactly on ticks


def test_velocity_unit_is_0_229_rpm_at_the_horn() -> None:
    u = JointUnits(1, 1.0, 0.0, XM430)
    assert u.dq_rad_s(1) == pytest.approx(0.229 * 2 * math.pi / 60)  # 0.02398 rad/s
    assert JointUnits(-1, 2.0, 0.0, XM430).dq_rad_s(10) == pytest.approx(-10 * 0.229 * 2 * math.pi / 60 / 2)
    assert u.velocity_units(u.dq_rad_s(123)) == 123


def test_torque_from_current_through_the_torque_constant_and_the_gear() -> None:
    u = JointUnits(1, 1.0, 0.0, XM430)
    kt = 4.1 / 2.3  # stall torque / stall current at 12 V
    assert u.tau_nm(100) == pytest.approx(100 * 0.00269 * kt)
    geared = JointUnits(-1, 3.0, 0.0, XM430)  # a joint turned by 3 horn turns: 3x the torque
    assert geared.tau_nm(100) == pytest.approx(-3 * 100 * 0.00269 * kt)
    assert geared.current_units(geared.tau_nm(-57)) == -57
    xm540 = JointUnits(1, 1.0, 0.0, MODELS["XM540-W270"])
    assert xm540.tau_nm(1) == pytest.approx(0.00269 * 10.6 / 4.4)


def test_xl430_torque_comes_from_present_load() -> None:
    u = JointUnits(1, 1.0, 0.0, MODELS["XL430-W250"])
    assert u.tau_nm(1000) == pytest.approx(1.5)  # 100.0 % of the stall torque
    assert u.current_limit_units(1.0) == 0  # no Current Limit item


def test_ranges_and_limits_round_outwards_and_follow_the_direction() -> None:
    u = JointUnits(-1, 1.0, 0.0, XM430)
    lo, hi = u.tick_range(-1.0, 0.5)
    assert lo <= u.ticks(0.5) and hi >= u.ticks(-1.0)  # direction -1: the ends swap
    assert lo < CENTER_TICKS < hi
    assert u.velocity_limit_units(2.5) == math.ceil(2.5 / (0.229 * 2 * math.pi / 60))
    assert u.current_limit_units(4.1) == math.ceil(2.3 / 0.00269)  # the stall current
    assert u.current_limit_units(100.0) == XM430.current_limit_max  # never beyond the model's
