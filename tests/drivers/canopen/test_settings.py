"""`[resource.settings]` of the canopen402 backend: every refusal names file, key, value."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

from orccadd.drivers.canopen.settings import load_canopen_settings
from orccadd.errors import ConfigError
from orccadd.robot import load_robot_config
from tests.conftest import UR5E, eds

FILE = "robot.toml"


def raw(eds_name: str = "canopen/e35.eds", **over: Any) -> dict[str, Any]:
    axes = [{"node_id": i + 1, "eds": str(eds(eds_name)), "gear_ratio": 100.0} for i in range(6)]
    return {"interface": "socketcand", "channel": "can0", "axes": axes, **over}


def ur5e(period_s: float = 0.002) -> Any:
    return dataclasses.replace(load_robot_config(UR5E), control_period_s=period_s)


def test_six_axes_at_500_hz_are_accepted_with_a_bus_load_warning(capsys: pytest.CaptureFixture[str]) -> None:
    s = load_canopen_settings(raw(), ur5e(), FILE)
    assert len(s.axes) == 6 and all(Path(p).is_file() for p in s.eds_paths)
    assert s.bus_kwargs() == {
        "interface": "socketcand",
        "host": "127.0.0.1",
        "port": 29536,
        "tcp_tune": True,  # TCP_NODELAY: a tick's frames are not held back by Nagle's algorithm
        "channel": "can0",
    }
    err = capsys.readouterr().err
    assert "warning: bus can0: bus load" in err and "bus_load_warn in [resource.settings]" in err
    load_canopen_settings({**raw(), "bus_load_warn": 0.85}, ur5e(), FILE)  # the integrator accepts it
    assert "bus load" not in capsys.readouterr().err
    with pytest.raises(ConfigError, match=r"bus_load_warn \(=0.95\) must be in \[0.1, 0.9\]"):
        load_canopen_settings({**raw(), "bus_load_warn": 0.95}, ur5e(), FILE)


def test_1_khz_is_refused_with_the_shortest_period_that_fits() -> None:
    with pytest.raises(ConfigError) as e:
        load_canopen_settings(raw(), ur5e(0.001), FILE)
    assert str(e.value).startswith("robot.toml: control_period_s (=0.001): bus can0: bus load")
    # worst case per cycle 55 + 12 × 135 = 1,675 bits; heartbeats 80/s × 65 bits
    # 1,675 / (0.9 × 1e6 - 5,200) = 1.872 ms
    assert "shortest period that fits is 1.88 ms" in str(e.value)


def test_csv_on_a_drive_without_0x60ff_is_refused_before_startup() -> None:
    with pytest.raises(ConfigError) as e:
        load_canopen_settings(raw("ros_canopen/Schunk.eds", mode="csv"), ur5e(), FILE)
    assert str(e.value) == (
        "robot.toml: resource.settings.axes[0] (shoulder_pan_joint) mode 'csv': cyclic synchronous "
        "velocity (csv) is not possible with Schunk.eds: it lacks 0x60FF target velocity (this drive "
        "can do: csp)"
    )


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda r: r["axes"].pop(), "resource.settings.axes has 5 entries, must have one per joint (6)"),
        (
            lambda r: r["axes"][3].update(node_id=1),
            "resource.settings.axes[3].node_id (=1) is also axes[0]'s",
        ),
        (
            lambda r: r["axes"][2].update(eds="nope.eds"),
            "resource.settings.axes[2].eds (='nope.eds') not found",
        ),
        (
            lambda r: r["axes"][0].update(node_id=128),
            "resource.settings.axes[0].node_id (=128) must be in [1, 127]",
        ),
        (lambda r: r.update(mode="pp"), "resource.settings.mode (='pp') must be one of 'csp', 'csv', 'cst'"),
        (lambda r: r.update(bitrate=500000), "resource.settings.bitrate is not a known key"),
    ],
)
def test_bad_settings(edit: Any, message: str) -> None:
    r = raw()
    edit(r)
    with pytest.raises(ConfigError) as e:
        load_canopen_settings(r, ur5e(), FILE)
    assert message in str(e.value)


# ---- several buses ---------------------------------------------------------------------------------
def two_buses(on_can1: int = 3, **over: Any) -> dict[str, Any]:
    """Six axes, the last `on_can1` on a second bus (node ids 1.. again there)."""
    r = raw(**over)
    for k, ax in enumerate(r["axes"][6 - on_can1 :]):
        ax.update(bus="can1", node_id=k + 1)
    r["buses"] = [{"channel": "can1", "port": 29537}]
    return r


def test_one_bus_configs_are_one_bus_with_every_axis() -> None:
    s = load_canopen_settings(raw(), ur5e(), FILE)
    (bus,) = s.bus_list()
    assert (bus.channel, bus.port, bus.axes) == ("can0", 29536, (0, 1, 2, 3, 4, 5))


def test_two_buses_at_1_khz_are_checked_and_accepted_per_bus(capsys: pytest.CaptureFixture[str]) -> None:
    s = load_canopen_settings(two_buses(), ur5e(0.001), FILE)
    can0, can1 = s.bus_list()
    assert (can0.channel, can0.port, can0.axes) == ("can0", 29536, (0, 1, 2))
    assert (can1.channel, can1.port, can1.axes) == ("can1", 29537, (3, 4, 5))
    assert can1.bus_kwargs()["port"] == 29537 and can1.interface == "socketcand"
    err = capsys.readouterr().err
    # 3 axes: worst case 55 + 6 × 135 = 865 bits per ms, 86.5 % + heartbeats: warned, not refused
    assert "warning: bus can0: bus load 72%-87%" in err and "warning: bus can1: bus load 72%-87%" in err


def test_an_overloaded_bus_is_refused_naming_it() -> None:
    with pytest.raises(ConfigError) as e:
        load_canopen_settings(two_buses(on_can1=5), ur5e(0.001), FILE)  # 1 axis on can0, 5 on can1
    assert str(e.value).startswith("robot.toml: control_period_s (=0.001): bus can1: bus load")
    assert "above 90%" in str(e.value)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda r: r["axes"][4].update(bus="can2"), "axes[4].bus (='can2') is no bus here (buses: can0"),
        (lambda r: r["axes"][4].update(node_id=1), "axes[4].node_id (=1) is also axes[3]'s (bus can1)"),
        (lambda r: r["buses"].append({"channel": "can0"}), "buses[1].channel (='can0') names a bus twice"),
        (
            lambda r: [ax.pop("bus") for ax in r["axes"][3:]],
            "resource.settings.axes[3].node_id (=1) is also axes[0]'s (bus can0)",
        ),
        (
            lambda r: r["buses"].append({"channel": "can2", "port": 29538}),
            "resource.settings.buses bus 'can2' carries no axis",
        ),
        (lambda r: r["buses"][0].update(baud=1), "resource.settings.buses[0].baud is not a known key"),
    ],
)
def test_bad_buses(edit: Any, message: str) -> None:
    r = two_buses()
    edit(r)
    with pytest.raises(ConfigError) as e:
        load_canopen_settings(r, ur5e(0.001), FILE)
    assert message in str(e.value)


def test_the_tpdo_wait_is_below_half_a_period() -> None:
    assert load_canopen_settings(two_buses(tpdo_wait_us=300), ur5e(0.001), FILE).tpdo_wait_us == 300
    with pytest.raises(ConfigError) as e:
        load_canopen_settings(two_buses(tpdo_wait_us=500), ur5e(0.001), FILE)
    assert "resource.settings.tpdo_wait_us (=500) must be below half the control period (500 µs)" in str(
        e.value
    )
