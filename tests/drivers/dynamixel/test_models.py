"""The model table (identity, units, modes) and the control-table items, against the simulator's
own tables (a second source written from the same e-Manual pages) and the SDK's constants."""

from __future__ import annotations

import pytest

from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel.models import BY_NUMBER, CURRENT, MODELS, POSITION, VELOCITY, model_name
from orccadd.dxlsim import models as sim_models
from orccadd.dxlsim import table as sim_table


@pytest.mark.parametrize("name", sorted(sim_models.MODELS))
def test_models_agree_with_the_simulator(name: str) -> None:
    ours, sim = MODELS[name], sim_models.MODELS[name]
    assert ours.model_number == sim.model_number
    assert ours.torque_constant_nm_a == pytest.approx(sim.torque_constant_nm_a)
    assert ours.current_unit_a == sim.current_unit_a
    assert ours.current_limit_max == sim.current_limit_max
    assert ours.no_load_speed_rad_s == pytest.approx(sim.no_load_speed_rad_s)


def test_every_model_the_issue_names_is_known_by_its_number() -> None:
    for name, number in (
        ("XM430-W350", 1020),
        ("XM540-W270", 1120),
        ("XH430-W350", 1010),
        ("XL430-W250", 1060),
    ):
        assert BY_NUMBER[number].name == name
    assert model_name(1020) == "XM430-W350 (1020)"
    assert "not one this backend knows" in model_name(9999)


def test_xl430_has_no_current_modes() -> None:
    xl = MODELS["XL430-W250"]
    assert not xl.has_current and CURRENT not in xl.modes
    assert {POSITION, VELOCITY} <= xl.modes
    assert all(m.has_current and CURRENT in m.modes for n, m in MODELS.items() if n != "XL430-W250")


def test_items_sit_where_the_simulators_table_has_them() -> None:
    ours = [v for v in vars(T).values() if isinstance(v, T.Item)]
    theirs = {i.name: i for i in sim_table.ITEMS}
    for item in ours:
        sim = theirs[item.name]
        assert (item.address, item.size, item.signed) == (sim.address, sim.size, sim.signed), item
        assert item.eeprom == sim.eeprom


def test_the_cyclic_block_is_current_velocity_position() -> None:
    assert (T.CYCLIC_START, T.CYCLIC_LENGTH) == (126, 10)
    assert T.PRESENT_POSITION.decode(T.PRESENT_POSITION.encode(-5)) == -5
    assert T.GOAL_CURRENT.encode(-2) == [0xFE, 0xFF]
