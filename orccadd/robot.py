"""Assembly: a robot config file → its typed config, dynamic model and Physical Resource.

The one place that brings `config`, `model` and `physres` together, so that each of them stays a
layer that imports only those below it. Everything above (the daemon, sessions, simulators,
benchmarks) builds robots through `load_robot` / `load_robot_config` / `create_resource`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from orccadd.config.robot import RobotConfig, read_robot_config
from orccadd.model import RobotModel
from orccadd.physres import PhysicalResource, backend_class


@dataclass(frozen=True)
class Robot:
    """A robot ready to configure: its config, model and (unconfigured) resource."""

    config: RobotConfig
    model: RobotModel
    resource: PhysicalResource


def load_robot_config(path: str | Path, *, check_model: bool = True) -> RobotConfig:
    """Read a robot config, check its backend's settings and (by default) its URDF.

    Raises `ConfigError` naming the file, key, value and what was allowed. Not for a tick.
    """
    cfg = read_robot_config(path)
    backend = backend_class(cfg.resource.backend, cfg.source)
    settings = backend.load_settings(cfg.resource.settings or {}, cfg, cfg.source)
    cfg = replace(cfg, backend_settings=settings)
    if check_model:
        RobotModel.from_config(cfg)  # raises ConfigError/ModelError on mismatch
    return cfg


def with_backend(cfg: RobotConfig, backend: str, **settings: Any) -> RobotConfig:
    """The same robot on another resource backend (e.g. `sim_process`), settings re-checked."""
    raw = {**(cfg.resource.settings or {}), **settings}
    cfg = replace(cfg, resource=replace(cfg.resource, backend=backend, settings=raw))
    return replace(
        cfg, backend_settings=backend_class(backend, cfg.source).load_settings(raw, cfg, cfg.source)
    )


def create_resource(cfg: RobotConfig, model: RobotModel | None = None) -> PhysicalResource:
    """Build (not configure) the resource a checked robot config names."""
    cls = backend_class(cfg.resource.backend, cfg.source)
    return cls(cfg, model if model is not None else RobotModel.from_config(cfg))


def load_robot(path: str | Path) -> Robot:
    """Config, model and resource of the robot config at `path`. Not for a tick."""
    cfg = load_robot_config(path, check_model=False)
    model = RobotModel.from_config(cfg)
    return Robot(cfg, model, create_resource(cfg, model))
