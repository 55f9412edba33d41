"""Robot config files mutated at the TOML-value level: `load_robot_config` returns a config or
raises a `ConfigError` naming the file, nothing else."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given

from orccadd.errors import ConfigError
from orccadd.robot import load_robot_config
from tests.fuzz.conftest import fuzz
from tests.fuzz.strategies import configs
from tests.fuzz.toml_text import (
    HOSTILE_PATHS,
    SEEDS,
    dumps,
    is_file_name,
    key_paths,
    seed_dict,
    value_at,
    with_value,
)


def load_outcome(path: Path, data: bytes) -> str:
    """'loaded' or 'refused'; any other exception propagates (a defect)."""
    path.write_bytes(data)
    try:
        load_robot_config(path)
    except ConfigError as e:
        assert str(path) in str(e), f"a ConfigError that does not name the file: {e}"
        return "refused"
    return "loaded"


@pytest.fixture(scope="module")
def config_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzzcfg") / "robot.toml"


@fuzz(max_examples=100, shrink=False)  # a failing config is shown whole
@given(data=configs())
def test_mutated_configs_load_or_are_refused(config_file: Path, data: bytes) -> None:
    load_outcome(config_file, data)


def test_hostile_file_names_are_config_errors(tmp_path: Path) -> None:
    """Every kind of file-name key of the shipped configs (URDF, mission directories, hold task,
    drive EDS; each on the first config that has it: simulated arms first, the slow CANopen one
    last) given each
    hostile name: a ConfigError naming the config file, or a config."""
    path = tmp_path / "robot.toml"
    failures, seen = [], set()
    for seed in sorted(SEEDS, key=lambda p: ("canopen" in p.name, not p.name.startswith("sim-"), p.name)):
        d = seed_dict(seed)
        for key in [p for p in key_paths(d) if is_file_name(value_at(d, p))]:
            shape = tuple(k if isinstance(k, str) else 0 for k in key)
            if shape in seen:
                continue
            seen.add(shape)
            for name in HOSTILE_PATHS:
                try:
                    load_outcome(path, dumps(with_value(d, key, name)).encode())
                except Exception as e:
                    failures.append(f"{seed.name} {key} = {name[:40]!r}: {type(e).__name__}: {str(e)[:150]}")
    assert not failures, "\n".join(failures)
