"""Shared fixtures: shipped configs, variants of them written to a temporary folder."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
UR5E = ROOT / "configs" / "robots" / "sim-ur5e.toml"
PANDA = ROOT / "configs" / "robots" / "sim-panda.toml"
MOVE_TASK = ROOT / "configs" / "tasks" / "move_joints.toml"
URDF_DIR = ROOT / "configs" / "urdf"


def variant_text(base: Path, *edits: tuple[str, str]) -> str:
    """The text of `base` with each (old, new) replaced once; `old` must be present."""
    text = base.read_text().replace('"../urdf/', f'"{URDF_DIR}/')
    for old, new in edits:
        assert old in text, f"{old!r} not in {base.name}"
        text = text.replace(old, new, 1)
    return text


def _variant_writer(tmp_path: Path, default_base: Path, default_name: str) -> Callable[..., Path]:
    def make(*edits: tuple[str, str], base: Path = default_base, name: str = default_name) -> Path:
        p = tmp_path / name
        p.write_text(variant_text(base, *edits))
        return p

    return make


@pytest.fixture
def robot_variant(tmp_path: Path) -> Callable[..., Path]:
    """Write a variant of a shipped robot config (`make(*(old, new), base=...)`); its path."""
    return _variant_writer(tmp_path, UR5E, "robot.toml")


@pytest.fixture
def task_variant(tmp_path: Path) -> Callable[..., Path]:
    """Write a variant of the shipped move task; returns its path."""
    return _variant_writer(tmp_path, MOVE_TASK, "task.toml")
