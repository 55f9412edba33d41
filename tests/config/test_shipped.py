"""`--config NAME`: a path, or a shipped robot config's name; `--list-configs`; `--version`."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from orccadd.config.shipped import list_configs, robot_config_path, shipped
from orccadd.errors import ConfigError
from tests.conftest import ROOT


def test_a_name_finds_the_shipped_config_and_a_path_is_taken_as_it_is(tmp_path: Path) -> None:
    assert robot_config_path("sim-ur5e") == ROOT / "configs/robots/sim-ur5e.toml"
    assert robot_config_path("sim-ur5e.toml") == ROOT / "configs/robots/sim-ur5e.toml"
    mine = tmp_path / "mine.toml"
    mine.write_text("")
    assert robot_config_path(str(mine)) == mine


def test_an_unknown_name_is_refused_with_the_shipped_ones() -> None:
    with pytest.raises(ConfigError, match=r"sim-ur6e: no such file, .*shipped: .*sim-ur5e.*--list-configs"):
        robot_config_path("sim-ur6e")


def test_orccadd_config_path_comes_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "sim-ur5e.toml").write_text("")
    monkeypatch.setenv("ORCCADD_CONFIG_PATH", str(tmp_path))
    assert robot_config_path("sim-ur5e") == tmp_path / "robots" / "sim-ur5e.toml"
    assert shipped("missions")["demo"] == ROOT / "configs/missions/demo.mission"  # the rest still found


def test_list_configs_and_version_from_the_command_line() -> None:
    text = list_configs()
    assert "sim-ur5e" in text and "demo_position" in text
    for argv, prog in ((["-m", "orccadd.daemon.rtproc"], "orccadd"), (["-m", "orccadd.cli"], "orccadctl")):
        out = subprocess.run([sys.executable, *argv, "--version"], capture_output=True, text=True, check=True)
        assert out.stdout.startswith(f"{prog} 0.") and "(protocol " in out.stdout
    argv = [sys.executable, "-m", "orccadd.daemon.rtproc", "--list-configs"]
    out = subprocess.run(argv, capture_output=True, text=True, check=True)
    assert "ur5e-rtde-sim" in out.stdout


def test_a_name_the_system_refuses_is_no_such_file_not_a_crash() -> None:
    """The protocol fuzzer's `load` of a 1000-letter bare name: the lookup's stat raised
    ENAMETOOLONG and the daemon answered "internal error"."""
    from orccadd.config.shipped import mission_path

    with pytest.raises(ConfigError, match="no such file, and no shipped mission"):
        mission_path("a" * 1000)
    with pytest.raises(ConfigError, match="no such file"):
        robot_config_path("a" * 1000)
