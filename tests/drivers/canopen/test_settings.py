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
    assert "warning: bus can0: bus load" in capsys.readouterr().err


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
