"""A mode switch in two phases: prepared outside the tick (when a task is built), performed in it."""

from __future__ import annotations

import pytest

from orccadd.errors import ConfigError, LifecycleError, ResourceError
from orccadd.robot import create_resource, load_robot_config
from orccadd.task.builder import build_task
from orccadd.task.spec import load_task_file
from orccadd.types import CommandMode
from tests.conftest import ROOT, UR5E


def test_perform_needs_prepare_and_prepare_needs_a_supported_mode() -> None:
    res = create_resource(load_robot_config(UR5E))
    res.configure()
    res.activate(CommandMode.TORQUE)
    with pytest.raises(LifecycleError, match="switch to position mode not prepared"):
        res.perform_mode_switch(CommandMode.POSITION)
    res.prepare_mode_switch(CommandMode.POSITION)
    res.perform_mode_switch(CommandMode.POSITION)
    assert res.mode is CommandMode.POSITION
    res.supported_modes = frozenset({CommandMode.TORQUE, CommandMode.POSITION})  # as a device narrows it
    with pytest.raises(ResourceError, match="cannot command velocity"):
        res.prepare_mode_switch(CommandMode.VELOCITY)


def test_building_a_task_prepares_its_mode() -> None:
    res = create_resource(load_robot_config(UR5E))
    res.configure()
    res.activate(CommandMode.TORQUE)
    spec = load_task_file(ROOT / "configs" / "tasks" / "move_joints_csp.toml")
    build_task(spec, res)
    res.perform_mode_switch(CommandMode.POSITION)  # no error: prepared by the build


def test_a_mode_the_device_refuses_to_prepare_refuses_the_task(monkeypatch: pytest.MonkeyPatch) -> None:
    res = create_resource(load_robot_config(UR5E))

    def refuse(mode: CommandMode) -> None:
        raise ResourceError(f"{res.name}: the drives cannot take {mode.name.lower()} mode")

    monkeypatch.setattr(res, "_on_prepare_mode_switch", refuse)
    spec = load_task_file(ROOT / "configs" / "tasks" / "move_joints_csp.toml")
    with pytest.raises(ConfigError, match="task.command.*cannot take position mode"):
        build_task(spec, res)
