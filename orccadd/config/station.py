"""A station: several Physical Resources in one daemon (an arm and its gripper, two arms).

The word "cell" is kept for robot PCs over Zenoh (`[cell]`, `orccadd.config.cellnet`): a
station is what one daemon drives; a cell is several stations' daemons working together.

A robot config with one `[resource]` is a station of one resource, read as before. A station
config lists its resources instead, each by the robot config that describes it on its own (its
model, joints, limits, backend, period, safe stop), with what differs here:

    name = "ur5e-gripper"

    [[resources]]
    name = "arm"                       # the name missions bind tasks to (`task T on arm ...`)
    config = "ur5e-rtde-sim.toml"      # relative to this file

    [[resources]]
    name = "gripper"
    config = "gripper-sim.toml"
    control_period_s = 0.008           # optional: its own period (default: the config's)
    settings = { port = "/tmp/ttyG" }  # optional: keys that replace its [resource.settings] ones
    loop = { overrun_limit = 10 }      # optional: its loop's [daemon] keys here (`PER_RESOURCE`)

    [daemon]                           # the station's: one socket, one automaton, one mission

The `[daemon]` keys of a resource's control loop come from its own config (`PER_RESOURCE`: its
Hold task, overrun limit, switch blend, watchdog, task timeout, tick); every other `[daemon]` key
(socket, roles, priorities, loads, logs, clients) is the station's, and a station's `[daemon]`
that sets a per-resource key is refused, naming the config where it belongs. A resource's `loop`
table replaces some of those keys for this station only: limits counted in periods (overruns in
a row, a stale heartbeat) are shorter in time when the station runs the resource at a shorter
period.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from orccadd.config.cellnet import CellNetConfig, load_cellnet
from orccadd.config.robot import DaemonConfig, RobotConfig, read_robot_config, read_toml
from orccadd.config.schema import field, load_dataclass
from orccadd.errors import ConfigError

PER_RESOURCE = (
    "hold_task",
    "overrun_limit",
    "switch_blend_s",
    "watchdog_stale_periods",
    "task_timeout_s",
    "tick",
)
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")  # a mission's identifier


@dataclass(frozen=True)
class ResourceEntry:
    """One `[[resources]]` table."""

    name: str = field()
    config: str = field()
    control_period_s: float = field(default=0.0, bounds=(0.0, 0.1))  # 0: the config's own
    settings: dict[str, Any] = field(default=None)  # type: ignore[assignment]
    loop: dict[str, Any] = field(default=None)  # type: ignore[assignment]


@dataclass(frozen=True)
class StationFile:
    name: str = field()
    resources: tuple[ResourceEntry, ...] = field(min_len=1)
    daemon: DaemonConfig = field(default=DaemonConfig())
    cell: Any = field(default=None)  # `[cell]`: this daemon as a peer of a cell of PCs


@dataclass(frozen=True)
class StationConfig:
    """The resources one daemon drives, each a whole `RobotConfig` (its `resource.name` the
    station's name for it, its `daemon` the station's but for its own Hold task)."""

    name: str
    source: str
    daemon: DaemonConfig
    resources: tuple[RobotConfig, ...]
    listed: bool = False  # written as a station ([[resources]]), not a one-resource robot config
    overridden: tuple[frozenset[str], ...] = ()  # per resource: the settings keys the station sets
    cell: CellNetConfig | None = None  # `[cell]`: the station's daemon a peer of a cell of PCs

    @classmethod
    def of(cls, cfg: RobotConfig) -> StationConfig:
        """The station of one resource that a robot config is."""
        return cls(cfg.name, cfg.source, cfg.daemon, (cfg,), cell=cfg.cell)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.resource.name for r in self.resources)

    def resource(self, name: str) -> RobotConfig:
        for r in self.resources:
            if r.resource.name == name:
                return r
        raise KeyError(name)

    def resolve(self, path: str) -> Path:
        """A path from the station's file, relative to its folder."""
        return (Path(self.source).parent / path).resolve()

    def with_resources(self, resources: tuple[RobotConfig, ...]) -> StationConfig:
        return replace(self, resources=resources)


def is_station_file(raw: dict[str, Any]) -> bool:
    return "resources" in raw


def read_station_config(path: str | Path) -> StationConfig:
    """Read a station config or a one-resource robot config (its form only: keys, types, bounds,
    joints, names; no backend, no URDF: `orccadd.robot.load_station_config` adds those)."""
    file = str(path)
    raw = read_toml(Path(path))
    if not is_station_file(raw):
        return StationConfig.of(read_robot_config(path))
    for key in ("resource", "model", "joints", "control_period_s", "safe_stop", "limits"):
        if key in raw:
            raise ConfigError(
                file,
                key,
                "belongs to a resource's own config: a station lists [[resources]], each with its `config`",
            )
    for key in PER_RESOURCE:
        if key in (raw.get("daemon") or {}):
            raise ConfigError(
                file,
                f"daemon.{key}",
                "belongs to each resource's loop: set it in that resource's own config "
                "(or in its `loop` table here)",
            )
    station = load_dataclass(StationFile, raw, file)
    here = Path(file).parent
    daemon = _absolute(station.daemon, here)
    seen: dict[str, int] = {}
    out: list[RobotConfig] = []
    for i, entry in enumerate(station.resources):
        key = f"resources[{i}]"
        if not NAME.match(entry.name):
            raise ConfigError(
                file, f"{key}.name", f"(={entry.name!r}) must be an identifier (letters, digits, _)"
            )
        if entry.name in seen:
            raise ConfigError(
                file, f"{key}.name", f"(={entry.name!r}) is resources[{seen[entry.name]}]'s name too"
            )
        seen[entry.name] = i
        if 0.0 < entry.control_period_s < 0.0001:
            raise ConfigError(
                file,
                f"{key}.control_period_s",
                f"(={entry.control_period_s!r}) must be 0 (the config's) or in [0.0001, 0.1]",
            )
        sub_path = (here / entry.config).resolve()
        if sub_path.is_file() and is_station_file(read_toml(sub_path)):
            raise ConfigError(
                file, f"{key}.config", f"(={entry.config!r}) is a station itself: name a resource's config"
            )
        if not sub_path.is_file():
            raise ConfigError(
                file, f"{key}.config", f"(={entry.config!r}): no such file (relative to {here})"
            )
        sub = read_robot_config(sub_path)
        if sub.cell is not None:
            raise ConfigError(
                file,
                f"{key}.config",
                f"(={entry.config!r}) has a [cell] table: a station's [cell] is in this file",
            )
        loop = _loop_keys(entry.loop or {}, file, f"{key}.loop")
        settings = {**(sub.resource.settings or {}), **(entry.settings or {})}
        out.append(
            replace(
                sub,
                resource=replace(sub.resource, name=entry.name, settings=settings),
                control_period_s=entry.control_period_s or sub.control_period_s,
                daemon=replace(
                    daemon,
                    hold_task=str(sub.resolve(sub.daemon.hold_task)),
                    **{k: getattr(sub.daemon, k) for k in PER_RESOURCE if k != "hold_task"} | loop,
                ),
            )
        )
    overridden = tuple(frozenset(e.settings or {}) for e in station.resources)
    cell = load_cellnet(station.cell, file, station.name) if station.cell is not None else None
    return StationConfig(
        station.name, file, daemon, tuple(out), listed=True, overridden=overridden, cell=cell
    )


def _loop_keys(table: dict[str, Any], file: str, key: str) -> dict[str, Any]:
    """A resource entry's `loop` table: `PER_RESOURCE` keys but its Hold task (a path of its own
    config), typed and bounded as in a `[daemon]` table."""
    allowed = [k for k in PER_RESOURCE if k != "hold_task"]
    for k in table:
        if k not in allowed:
            raise ConfigError(
                file, f"{key}.{k}", f"is not a key of a resource's loop (allowed: {', '.join(allowed)})"
            )
    checked = load_dataclass(DaemonConfig, table, file, prefix=key)
    return {k: getattr(checked, k) for k in table}


def _absolute(d: DaemonConfig, here: Path) -> DaemonConfig:
    """The station's daemon paths made absolute: each resource's config resolves them alike."""

    def absolute(p: str) -> str:
        return str((here / p).resolve())

    return replace(
        d,
        hold_task=absolute(d.hold_task),
        mission_dirs=tuple(absolute(p) for p in d.mission_dirs),
        task_dirs=tuple(absolute(p) for p in d.task_dirs),
        log_dir=absolute(d.log_dir) if d.log_dir else "",
    )


def override_key(station: StationConfig, index: int, err: ConfigError) -> ConfigError:
    """A backend's error about a setting the station overrides, named at the station's key."""
    prefix = "resource.settings."
    if not station.listed or not err.key.startswith(prefix):
        return err
    rest = err.key.removeprefix(prefix)
    if re.split(r"[.\[]", rest, maxsplit=1)[0] in station.overridden[index]:
        return ConfigError(station.source, f"resources[{index}].settings.{rest}", err.detail)
    return err


def pick_resource(station: StationConfig, backends: tuple[str, ...], name: str = "") -> RobotConfig:
    """The resource a device simulator serves from `station`: the one named `name`, or the station's
    only resource on one of `backends` (a one-resource robot config: its resource, whatever its
    backend, as before). `ConfigError` naming the file if there is none, or several to choose from."""
    if not station.listed and not name:
        return station.resources[0]
    if name:
        try:
            return station.resource(name)
        except KeyError:
            raise ConfigError(
                station.source, "resources", f"has no resource {name!r} (it has: {', '.join(station.names)})"
            ) from None
    mine = [r for r in station.resources if r.resource.backend in backends]
    if len(mine) == 1:
        return mine[0]
    kinds = " or ".join(backends)
    if not mine:
        raise ConfigError(
            station.source, "resources", f"has no {kinds} resource (it has: {', '.join(station.names)})"
        )
    names = ", ".join(r.resource.name for r in mine)
    raise ConfigError(
        station.source, "resources", f"has several {kinds} resources ({names}): name one with --resource"
    )
