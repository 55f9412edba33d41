"""Station configs: several resources, each by its own robot config, checked as a whole."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.config.station import pick_resource, read_station_config
from orccadd.errors import ConfigError
from orccadd.robot import load_station_config, with_backend
from tests.conftest import ROOT

ROBOTS = ROOT / "configs" / "robots"


def write(tmp: Path, text: str) -> Path:
    p = tmp / "station.toml"
    p.write_text(text)
    return p


def entry(name: str, config: str, extra: str = "") -> str:
    return f'[[resources]]\nname = "{name}"\nconfig = "{ROBOTS / config}"\n{extra}\n'


def test_a_one_resource_robot_config_is_a_cell_of_one() -> None:
    station = load_station_config(ROBOTS / "ur5e-rtde-sim.toml")
    assert station.names == ("arm",) and not station.listed
    assert station.resources[0].backend_settings is not None


def test_a_cell_names_its_resources_with_their_own_periods_and_hold_tasks(tmp_path: Path) -> None:
    text = 'name = "c"\n' + entry("left", "sim-ur5e.toml", "control_period_s = 0.001")
    text += entry("right", "sim-ur5e.toml") + entry("gripper", "gripper-sim.toml")
    station = load_station_config(write(tmp_path, text))
    assert station.names == ("left", "right", "gripper")
    assert [r.control_period_s for r in station.resources] == [0.001, 0.002, 0.005]
    assert Path(station.resource("gripper").daemon.hold_task).name == "gripper_hold.toml"
    assert Path(station.resource("left").daemon.hold_task).name == "hold.toml"
    # the station's daemon paths are its own, relative to its file
    assert station.daemon.mission_dirs == (str((tmp_path / "../missions").resolve()),)


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        (
            entry("arm", "sim-ur5e.toml") + entry("arm", "sim-panda.toml"),
            "resources[1].name",
            "resources[0]'s name too",
        ),
        (entry("left arm", "sim-ur5e.toml"), "resources[0].name", "identifier"),
        (entry("a", "nowhere.toml"), "resources[0].config", "no such file"),
        (
            entry("a", "sim-ur5e.toml", "control_period_s = 0.00001"),
            "resources[0].control_period_s",
            "0.0001",
        ),
        (entry("a", "sim-ur5e.toml", "colour = 1"), "resources[0].colour", "not a known key"),
        (
            entry("g1", "gripper-sim.toml") + entry("g2", "gripper-sim.toml"),
            "resources[1]",
            "serial port /tmp/orccadd-gripper, which resources[0] (='g1') holds",
        ),
        (
            entry("a", "ur5e-rtde-sim.toml") + entry("b", "ur5e-rtde-sim.toml"),
            "resources[1]",
            "UR controller at 127.0.0.1",
        ),
        (
            entry("a", "gripper-sim.toml", "settings = { baud_rate = 12 }"),
            "resources[0].settings.baud_rate",
            "(=12)",
        ),
    ],
)
def test_a_wrong_cell_is_refused_naming_the_file_and_key(
    tmp_path: Path, text: str, key: str, words: str
) -> None:
    path = write(tmp_path, 'name = "c"\n' + text)
    with pytest.raises(ConfigError) as info:
        load_station_config(path)
    assert info.value.file == str(path) and info.value.key == key, str(info.value)
    assert words in str(info.value)


def test_two_grippers_on_their_own_ports_are_a_cell(tmp_path: Path) -> None:
    text = entry("g1", "gripper-sim.toml") + entry(
        "g2", "gripper-sim.toml", 'settings = { port = "/tmp/g2" }'
    )
    station = load_station_config(write(tmp_path, 'name = "c"\n' + text))
    assert station.resource("g2").backend_settings.port == "/tmp/g2"


def test_a_cell_takes_no_resource_keys_of_its_own(tmp_path: Path) -> None:
    path = write(tmp_path, 'name = "c"\ncontrol_period_s = 0.001\n' + entry("a", "sim-ur5e.toml"))
    with pytest.raises(ConfigError, match="control_period_s belongs to a resource's own config"):
        read_station_config(path)


def test_a_cell_of_cells_is_refused(tmp_path: Path) -> None:
    inner = write(tmp_path, 'name = "in"\n' + entry("a", "sim-ur5e.toml"))
    outer = tmp_path / "outer.toml"
    outer.write_text(f'name = "out"\n[[resources]]\nname = "x"\nconfig = "{inner}"\n')
    with pytest.raises(ConfigError, match="is a station itself"):
        read_station_config(outer)


def test_a_resources_loop_keys_are_its_own_and_the_cell_may_not_set_them(tmp_path: Path) -> None:
    text = 'name = "c"\n' + entry("g", "gripper-sim.toml") + entry("a", "ur5e-rtde.toml")
    station = read_station_config(write(tmp_path, text))
    assert station.resource("g").daemon.overrun_limit == 25  # gripper-sim.toml's
    assert station.resource("a").daemon.overrun_limit == 5  # ur5e-rtde.toml's
    path = write(tmp_path, 'name = "c"\n' + entry("a", "sim-ur5e.toml") + "[daemon]\noverrun_limit = 9\n")
    with pytest.raises(ConfigError, match="daemon.overrun_limit belongs to each resource's loop"):
        read_station_config(path)


def test_a_cell_may_set_a_resources_loop_keys_in_its_entry(tmp_path: Path) -> None:
    """A resource run at a shorter period than its config's keeps its tolerances in time only
    with more periods: the entry's `loop` table sets them for this station (checked as in [daemon])."""
    loop = "control_period_s = 0.001\nloop = { overrun_limit = 50, watchdog_stale_periods = 80 }"
    station = read_station_config(
        write(tmp_path, 'name = "c"\n' + entry("l", "sim-ur5e.toml", loop) + entry("r", "sim-ur5e.toml"))
    )
    left, right = station.resource("l").daemon, station.resource("r").daemon
    assert (left.overrun_limit, left.watchdog_stale_periods) == (50, 80)
    assert right.overrun_limit == 25 and left.socket == right.socket  # the other one's own; one socket
    for bad, why in (
        (
            "loop = { socket = 'x' }",
            r"resources\[0\]\.loop\.socket is not a key of a resource's loop \(allowed: overrun_limit",
        ),
        ("loop = { hold_task = 'x.toml' }", r"resources\[0\]\.loop\.hold_task is not a key"),
        ("loop = { overrun_limit = 0 }", r"resources\[0\]\.loop\.overrun_limit"),
        ("loop = { overrun_limit = 'many' }", r"resources\[0\]\.loop\.overrun_limit"),
    ):
        with pytest.raises(ConfigError, match=why):
            read_station_config(write(tmp_path, 'name = "c"\n' + entry("l", "sim-ur5e.toml", bad)))


def test_the_dual_arm_station_keeps_its_fast_arms_tolerances_in_time() -> None:
    """dual-arm-sim runs `left` at 1 kHz from sim-ur5e.toml's 500 Hz: the same 50 ms of late
    ticks and 100 ms without a command (the daemon's plant process, by default) as `right`."""
    station = load_station_config(ROBOTS / "dual-arm-sim.toml")
    for name in ("left", "right"):
        r = with_backend(station.resource(name), "sim_process")
        s = r.backend_settings
        assert r.daemon.overrun_limit * r.control_period_s == pytest.approx(0.05)
        for periods in (s.watchdog_periods, s.heartbeat_timeout_periods):
            assert s.periods(periods, r.control_period_s) * r.control_period_s == pytest.approx(0.1)


def test_a_simulator_serves_the_one_resource_of_its_bus_or_the_one_named() -> None:
    station = read_station_config(ROBOTS / "ur5e-gripper-sim.toml")
    assert pick_resource(station, ("dynamixel",)).resource.name == "gripper"
    assert pick_resource(station, ("ur_rtde",)).resource.name == "arm"
    two = read_station_config(ROBOTS / "dual-arm-grippers-sim.toml")
    with pytest.raises(ConfigError, match=r"several dynamixel resources \(left_hand, right_hand\): name one"):
        pick_resource(two, ("dynamixel",))
    assert (
        pick_resource(two, ("dynamixel",), "right_hand").resource.settings["port"]
        == "/tmp/orccadd-right-hand"
    )
    with pytest.raises(ConfigError, match="has no resource 'thumb'"):
        pick_resource(two, ("dynamixel",), "thumb")
    with pytest.raises(ConfigError, match="has no canopen402 resource"):
        pick_resource(two, ("canopen402",))


def test_two_plants_on_one_fixed_control_port_are_refused(tmp_path: Path, robot_variant) -> None:  # type: ignore[no-untyped-def]
    robot = robot_variant(
        ('backend = "sim"', 'backend = "sim_process"'),
        ("seed = 1\n", "seed = 1\nplant_control_port = 30300\n"),
    )
    path = write(tmp_path, 'name = "c"\n' + entry("a", str(robot)) + entry("b", str(robot)))
    with pytest.raises(ConfigError, match=r"the plant control port 127.0.0.1:30300, which resources\[0\]"):
        load_station_config(path)
    ok = entry("a", str(robot)) + entry("b", str(robot), "settings = { plant_control_port = 0 }")
    assert load_station_config(write(tmp_path, 'name = "c"\n' + ok)).names == ("a", "b")
