"""Robot-Task files (TOML): modules, wires, resource, period, and the reactive shell.

Example (configs/tasks/move_joints.toml)::

    [task]
    name = "MoveJoints"
    resource = "arm"
    command = "torque"              # torque | velocity | position

    wires = ["arm.q -> traj.q", ..., "ct.tau -> arm.tau_cmd"]   # before the first table

    [modules.traj]
    type = "ruckig_trajectory"
    target_rad = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]   # parameters of the module

    [modules.ct]
    type = "computed_torque"
    kp = 400.0

    [[preconditions]]               # conditions on measured signals, with a timeout
    name = "AtRest"
    signal = "arm.dq"
    max_abs_below = 0.05
    timeout_s = 1.0

    [events]
    post = "reached.fired"
    [[events.T1]]                    # local reaction: set parameters
    name = "Slow"
    when = "track_soft.fired"
    set = { "traj.speed_scale" = 0.5 }
    [[events.T2]]
    name = "TrackingLost"
    when = "track.fired"
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from orccadd.config.robot import parse_toml, read_toml
from orccadd.config.schema import field, load_dataclass
from orccadd.errors import ConfigError
from orccadd.types import CommandMode, TaskInterface

INF = float("inf")


@dataclass(frozen=True)
class TaskHeader:
    name: str = field()
    resource: str = field()
    command: Literal["torque", "velocity", "position"] = field()
    joints: tuple[str, ...] = field(default=())  # empty: all joints of the resource
    period_s: float = field(default=0.0, bounds=(0.0, 1.0))  # 0: the robot's control period
    # running longer is the type 3 `Timeout` (safe stop): 0 takes the robot's
    # `[daemon] task_timeout_s`; `inf` says the task may run forever (no `Timeout` then)
    timeout_s: float = field(default=0.0, bounds=(0.0, INF))


@dataclass(frozen=True)
class PreconditionSpec:
    name: str = field()
    signal: str = field()
    timeout_s: float = field(bounds=(0.0, 3600.0), open_lo=True)
    max_abs_below: float = field(default=INF, bounds=(0.0, INF), open_lo=True)
    within: tuple[float, ...] = field(default=())  # [lo, hi] for every element


@dataclass(frozen=True)
class EventSpec:
    name: str = field()
    when: str = field()
    set: dict[str, Any] = field(default=None)  # type: ignore[assignment]  # T1 only


@dataclass(frozen=True)
class EventsSpec:
    post: str = field(default="")
    T1: tuple[EventSpec, ...] = field(default=())
    T2: tuple[EventSpec, ...] = field(default=())
    T3: tuple[EventSpec, ...] = field(default=())
    sync: tuple[EventSpec, ...] = field(default=())


@dataclass(frozen=True)
class ModuleSpec:
    name: str
    type: str
    parameters: dict[str, Any]


@dataclass(frozen=True)
class TaskSpec:
    """A Robot-Task as declared in a file, checked for form (wiring is checked by the builder)."""

    source: str
    task: TaskHeader
    modules: tuple[ModuleSpec, ...]
    wires: tuple[str, ...]
    preconditions: tuple[PreconditionSpec, ...]
    events: EventsSpec


TOP_KEYS = ("task", "modules", "wires", "preconditions", "events")


def parse_task(raw: dict[str, Any], source: str) -> TaskSpec:
    """Check a task table strictly (unknown keys are errors)."""
    for k in raw:
        if k not in TOP_KEYS:
            raise ConfigError(source, k, f"is not a known key (allowed here: {', '.join(TOP_KEYS)})")
    if "task" not in raw:
        raise ConfigError(source, "task", "is missing (a table with name, resource, command)")
    header = load_dataclass(TaskHeader, raw["task"], source, "task")
    if not header.name.isidentifier():
        raise ConfigError(
            source, "task.name", f"(={header.name!r}) must be an identifier (letters, digits, _)"
        )
    modules_raw = raw.get("modules", {})
    if not isinstance(modules_raw, dict) or not modules_raw:
        raise ConfigError(source, "modules", "must be a table of at least one module")
    modules = []
    for mname, body in modules_raw.items():
        key = f"modules.{mname}"
        if not isinstance(body, dict):
            raise ConfigError(source, key, "must be a table with a 'type'")
        if not mname.isidentifier():
            raise ConfigError(source, key, f"(={mname!r}) module names must be identifiers")
        if "type" not in body or not isinstance(body["type"], str):
            raise ConfigError(source, f"{key}.type", "is missing (the module type, e.g. 'computed_torque')")
        params = {k: v for k, v in body.items() if k != "type"}
        for misplaced in ("wires", "preconditions", "events"):
            if misplaced in params:
                raise ConfigError(
                    source,
                    f"{key}.{misplaced}",
                    f"belongs at the top level: put '{misplaced} = ...' before the "
                    "first [table] of the file (TOML puts it in the table above)",
                )
        modules.append(ModuleSpec(mname, body["type"], params))
    wires = raw.get("wires", [])
    if not isinstance(wires, list) or not all(isinstance(w, str) for w in wires):
        raise ConfigError(source, "wires", "must be a list of strings like 'traj.q_des -> ct.q_des'")
    pre_raw = raw.get("preconditions", [])
    if not isinstance(pre_raw, list):
        raise ConfigError(source, "preconditions", "must be an array of tables ([[preconditions]])")
    pres = tuple(
        load_dataclass(PreconditionSpec, p, source, f"preconditions[{i}]") for i, p in enumerate(pre_raw)
    )
    for i, p in enumerate(pres):
        if p.within and len(p.within) != 2:
            raise ConfigError(source, f"preconditions[{i}].within", f"(={list(p.within)!r}) must be [lo, hi]")
        if not p.within and p.max_abs_below == INF:
            raise ConfigError(source, f"preconditions[{i}]", "needs a test: max_abs_below or within")
    events = load_dataclass(EventsSpec, raw.get("events", {}), source, "events")
    for kind in ("T2", "T3", "sync"):
        for i, e in enumerate(getattr(events, kind)):
            if e.set is not None:
                raise ConfigError(
                    source,
                    f"events.{kind}[{i}].set",
                    "is only for type 1 exceptions (a local reaction)",
                )
    for kind in ("T1", "T2", "T3", "sync"):
        names = [e.name for e in getattr(events, kind)]
        for i, n in enumerate(names):
            if not n.isidentifier():
                raise ConfigError(source, f"events.{kind}[{i}].name", f"(={n!r}) must be an identifier")
            if names.index(n) != i:
                raise ConfigError(source, f"events.{kind}[{i}].name", f"(={n!r}) is declared twice")
    return TaskSpec(source, header, tuple(modules), tuple(wires), pres, events)


def load_task_file(path: str | Path) -> TaskSpec:
    """Read a task file. Not for a tick."""
    return parse_task(read_toml(Path(path)), str(path))


def parse_task_text(data: bytes, source: str) -> TaskSpec:
    """A task file's content, read from `source` (its name, for errors). Not for a tick."""
    return parse_task(parse_toml(data, source), source)


def interface_of(spec: TaskSpec) -> TaskInterface:
    """What the procedure compiler sees of a task file (built-in events excluded)."""
    t = spec.task
    return TaskInterface(
        source=spec.source,
        resource=t.resource,
        command=CommandMode[t.command.upper()],
        joints=t.joints,
        modules=tuple(m.name for m in spec.modules),
        has_post=bool(spec.events.post),
        has_pre=bool(spec.preconditions),
        t2=tuple(e.name for e in spec.events.T2),
        t3=tuple(e.name for e in spec.events.T3),
        sync=tuple(e.name for e in spec.events.sync),
        times_out=t.timeout_s != INF,
    )


def read_task_interface(path: Path) -> TaskInterface:
    """The `TaskFileReader` the procedure compiler takes: read, check and summarise a task file."""
    return interface_of(load_task_file(path))
