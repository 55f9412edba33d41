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
from orccadd.config.station import StationConfig, override_key, read_station_config
from orccadd.errors import ConfigError
from orccadd.model import RobotModel
from orccadd.physres import PhysicalResource, backend_class
from orccadd.physres.description import check_description


@dataclass(frozen=True)
class Robot:
    """A robot ready to configure: its config, model and (unconfigured) resource."""

    config: RobotConfig
    model: RobotModel
    resource: PhysicalResource


def load_robot_config(path: str | Path, *, check_model: bool = True) -> RobotConfig:
    """Read a robot config, check its backend's settings, what the backend's description rules
    out, and (by default) its URDF.

    Raises `ConfigError` naming the file, key, value and what was allowed. Not for a tick.
    """
    cfg = read_robot_config(path)
    backend = backend_class(cfg.resource.backend, cfg.source)
    settings = backend.load_settings(cfg.resource.settings or {}, cfg, cfg.source)
    return _checked(replace(cfg, backend_settings=settings), backend, check_model)


def load_station_config(path: str | Path, *, check_model: bool = True) -> StationConfig:
    """Read a station config (or a one-resource robot config: a station of one), each resource
    checked as `load_robot_config` checks one, and none claiming what another holds (a serial
    port, a CAN bus, a controller). `ConfigError` naming the file, key, value and what was allowed."""
    station = read_station_config(path)
    out: list[RobotConfig] = []
    claimed: dict[str, int] = {}
    for i, cfg in enumerate(station.resources):
        backend = backend_class(cfg.resource.backend, cfg.source)
        try:
            settings = backend.load_settings(cfg.resource.settings or {}, cfg, cfg.source)
        except ConfigError as e:
            raise override_key(station, i, e) from None
        cfg = _checked(replace(cfg, backend_settings=settings), backend, check_model)
        for claim in backend.claims(cfg):
            if claim in claimed:
                j = claimed[claim]
                raise ConfigError(
                    station.source,
                    f"resources[{i}]",
                    f"(={cfg.resource.name!r}) claims {claim}, which resources[{j}] "
                    f"(={station.resources[j].resource.name!r}) holds: one device, one resource",
                )
            claimed[claim] = i
        out.append(cfg)
    return station.with_resources(tuple(out))


def _checked(cfg: RobotConfig, backend: type[PhysicalResource], check_model: bool) -> RobotConfig:
    description = backend.describe(cfg)
    model = RobotModel.from_config(cfg) if check_model else None  # ConfigError/ModelError on mismatch
    # without the model, an arm is taken as loaded by gravity (the safe assumption)
    check_description(cfg, description, gravity_loaded=model.gravity_loaded() if model else True)
    return cfg


def with_backend(cfg: RobotConfig, backend: str, **settings: Any) -> RobotConfig:
    """The same robot on another resource backend (e.g. `sim_process`), settings re-checked."""
    raw = {**(cfg.resource.settings or {}), **settings}
    cfg = replace(cfg, resource=replace(cfg.resource, backend=backend, settings=raw))
    cls = backend_class(backend, cfg.source)
    return _checked(replace(cfg, backend_settings=cls.load_settings(raw, cfg, cfg.source)), cls, False)


SIMULATED = ("sim", "sim_process")


def simulated(cfg: RobotConfig) -> RobotConfig:
    """The same robot on the simulated arm (`orccadd --simulate`): its model, joints, limits,
    period, tool and daemon settings unchanged, its bus's settings dropped (nothing is opened),
    the arm starting at its home position. A simulated resource is returned as it is."""
    if cfg.resource.backend in SIMULATED:
        return cfg
    home = [j.home_rad for j in cfg.joints]
    bare = replace(cfg, resource=replace(cfg.resource, settings={}))
    return with_backend(bare, "sim", initial_q_rad=home)


def create_resource(cfg: RobotConfig, model: RobotModel | None = None) -> PhysicalResource:
    """Build (not configure) the resource a checked robot config names."""
    cls = backend_class(cfg.resource.backend, cfg.source)
    return cls(cfg, model if model is not None else RobotModel.from_config(cfg))


def load_robot(path: str | Path) -> Robot:
    """Config, model and resource of the robot config at `path`. Not for a tick."""
    cfg = load_robot_config(path, check_model=False)
    model = RobotModel.from_config(cfg)
    return Robot(cfg, model, create_resource(cfg, model))


def station_as_run(station: StationConfig, simulate: bool, in_process_sim: bool) -> StationConfig:
    """The station as the daemon runs it: every resource simulated (`--simulate`: its model,
    limits and period; no bus opened), a simulated arm in a process of its own unless
    `in_process_sim`, like a real arm outside the controller. The real-time process and each
    unit process apply it alike."""
    if simulate:
        station = station.with_resources(tuple(simulated(c) for c in station.resources))
    if not in_process_sim:
        station = station.with_resources(
            tuple(
                with_backend(c, "sim_process") if c.resource.backend == "sim" else c
                for c in station.resources
            )
        )
    return station
