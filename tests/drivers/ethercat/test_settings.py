"""`[resource.settings]` of the `ethercat402` backend: what the shipped configs give, and each
refusal naming the file, the key, the value and what was allowed."""

from __future__ import annotations

from pathlib import Path

import pytest

from orccadd.drivers.canopen.capabilities import object_dictionary
from orccadd.drivers.ethercat.pdo import layout_for
from orccadd.errors import ConfigError
from orccadd.robot import load_robot_config
from tests.conftest import ROOT

SIM = ROOT / "configs/robots/ethercat-6axis-sim.toml"
ECAT_EDS = ROOT / "configs/eds/orccadd-cia402-ecat.eds"


def variant(tmp_path: Path, *edits: tuple[str, str]) -> Path:
    text = SIM.read_text().replace('"../', f'"{ROOT / "configs"}/')
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    path = tmp_path / "ecat.toml"
    path.write_text(text)
    return path


def test_the_shipped_configs_load() -> None:
    for name in ("ethercat-6axis-sim.toml", "ethercat-6axis.toml"):
        s = load_robot_config(ROOT / "configs/robots" / name).backend_settings
        assert len(s.slaves) == 6 and s.mode == "csp" and s.distributed_clocks
        assert all(Path(p).name == "orccadd-cia402-ecat.eds" for p in s.eds_paths)


def test_a_slave_per_joint(tmp_path: Path) -> None:
    text = SIM.read_text()
    last = text.rindex("[[resource.settings.slaves]]")
    cut = text[:last] + text[text.index("[safe_stop]") :]
    path = tmp_path / "five.toml"
    path.write_text(cut.replace('"../', f'"{ROOT / "configs"}/'))
    with pytest.raises(ConfigError, match=r"resource\.settings\.slaves.*5 entries.*one per joint \(6\)"):
        load_robot_config(path)


def test_a_description_not_found_is_named(tmp_path: Path) -> None:
    path = variant(
        tmp_path, (f'eds = "{ROOT / "configs"}/eds/orccadd-cia402-ecat.eds"', 'eds = "nowhere.eds"')
    )
    with pytest.raises(ConfigError, match=r"slaves\[0\]\.eds.*nowhere\.eds.*not found"):
        load_robot_config(path)


def test_an_interface_name_that_cannot_be_one_is_refused(tmp_path: Path) -> None:
    path = variant(tmp_path, ('interface = "ecm0"', 'interface = "eth 1; rm"'))
    with pytest.raises(ConfigError, match=r"resource\.settings\.interface.*not a network interface name"):
        load_robot_config(path)


def test_a_pdo_the_description_lacks_is_refused(tmp_path: Path) -> None:
    path = variant(tmp_path, ("revision = 0x00000001", "revision = 0x00000001\nrx_pdo = 0x1601"))
    with pytest.raises(ConfigError, match=r"slaves\[0\].*PDO 0x1601 is not in orccadd-cia402-ecat\.eds"):
        load_robot_config(path)


def test_the_layout_maps_every_cyclic_mode_and_the_actual_values() -> None:
    lay = layout_for(object_dictionary(ECAT_EDS, 1))
    assert lay.rx == (0x6040, 0x607A, 0x60FF, 0x6071, 0x6060)
    assert lay.tx == (0x6041, 0x6064, 0x606C, 0x6077, 0x6061, 0x603F)
    assert (lay.rx_format, lay.tx_format) == ("<Hiihb", "<HiihbH")
    assert (lay.rx_bytes, lay.tx_bytes) == (13, 15)
    assert lay.entries(transmit=False)[1] == 0x607A0020
