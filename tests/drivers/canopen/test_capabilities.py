"""Drive capabilities from public EDS/DCF files nobody on this project wrote."""

from __future__ import annotations

import pytest

from orccadd.drivers.canopen.capabilities import read_capabilities
from tests.conftest import eds


@pytest.mark.parametrize(
    ("file", "modes"),
    [
        ("canopen/e35.eds", {"csp", "csv", "cst"}),
        ("ros_canopen/Elmo.dcf", {"csp", "csv", "cst"}),
        ("ros_canopen/technosoft.eds", {"csp", "csv", "cst"}),
        ("ros2_canopen/canopen_tests_config_cia402_cia402_slave.eds", {"csp", "csv"}),
        ("ros2_canopen/canopen_tests_config_robot_control_prbt_0_1.dcf", {"csp"}),
        ("ros_canopen/Schunk.eds", {"csp"}),
        ("ros_canopen/PRL120.eds", set()),
    ],
)
def test_modes_from_the_object_dictionary(file: str, modes: set[str]) -> None:
    caps = read_capabilities(eds(file))
    assert set(caps.modes) == modes
    assert caps.rpdos >= 2 and caps.tpdos >= 4


def test_csv_without_0x60ff_is_refused_naming_the_file_and_the_object() -> None:
    caps = read_capabilities(eds("ros_canopen/Schunk.eds"))
    caps.require("csp")
    with pytest.raises(ValueError) as e:
        caps.require("csv")
    assert str(e.value) == (
        "cyclic synchronous velocity (csv) is not possible with Schunk.eds: it lacks 0x60FF target "
        "velocity (this drive can do: csp)"
    )


def test_cst_without_torque_objects_and_unknown_modes() -> None:
    caps = read_capabilities(eds("ros2_canopen/canopen_tests_config_cia402_cia402_slave.eds"))
    with pytest.raises(ValueError, match="lacks 0x6071 target torque, 0x6077 torque actual value"):
        caps.require("cst")
    with pytest.raises(ValueError, match="unknown mode 'pp'"):
        caps.require("pp")


def test_an_object_that_cannot_be_mapped_counts_as_missing() -> None:
    caps = read_capabilities(eds("ros_canopen/PRL120.eds"))
    with pytest.raises(ValueError, match="lacks 0x607A target position"):
        caps.require("csp")


def test_supported_drive_modes_hint() -> None:
    assert not read_capabilities(eds("ros_canopen/Elmo.dcf")).hint_excludes("cst")  # 0x3ED: 7, 8, 9
    assert read_capabilities(eds("ros_canopen/technosoft.eds")).hint_excludes("csp")  # 0x1F0065
