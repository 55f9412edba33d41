"""Drive capabilities from public EDS/DCF files nobody on this project wrote."""

from __future__ import annotations

from pathlib import Path

import canopen
import pytest

from orccadd.drivers.canopen.capabilities import consumer_entry, read_capabilities
from tests.canopen_rig import edit_dcf
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


def elmo_with(tmp_path: Path, **entries: str) -> Path:
    """Elmo.dcf with 0x1016's sub-objects set (`sub0="1"`, `sub1="0x00050064"`)."""
    edits = {f"1016{key}": {"DefaultValue": value} for key, value in entries.items()}
    if entries.get("sub0") == "0":
        edits["1016sub0"]["LowLimit"] = "0"
    return edit_dcf(eds("ros_canopen/Elmo.dcf"), tmp_path / "elmo.dcf", edits)


def od(path: Path) -> canopen.ObjectDictionary:
    return canopen.import_od(str(path), 1)


def test_the_controller_takes_a_free_heartbeat_consumer_entry_or_its_own(tmp_path: Path) -> None:
    assert consumer_entry(od(eds("ros_canopen/Elmo.dcf")), 0x7F) == 1
    assert consumer_entry(od(elmo_with(tmp_path, sub1="0x00050064")), 0x7F) == 2  # sub 1 watches node 5
    assert consumer_entry(od(elmo_with(tmp_path, sub2="0x007F0096")), 0x7F) == 2  # already ours


def test_too_few_heartbeat_consumer_entries_say_what_is_missing(tmp_path: Path) -> None:
    with pytest.raises(
        ValueError, match=r"0x1016 has 0 consumer heartbeat entries \(number of entries, sub 0\)"
    ):
        consumer_entry(od(elmo_with(tmp_path, sub0="0")), 0x7F)
    with pytest.raises(
        ValueError, match=r"all 1 consumer heartbeat entries of 0x1016 are taken \(sub 1 watches node 5\)"
    ):
        consumer_entry(od(elmo_with(tmp_path, sub0="1", sub1="0x00050064")), 0x7F)
    with pytest.raises(ValueError, match="has no heartbeat consumer object 0x1016"):
        consumer_entry(od(eds("canopen/e35.eds")), 0x7F)
