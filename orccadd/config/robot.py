"""Robot configuration: model, joints and their limits, resource backend, period, safe stop.

Loaded from `configs/robots/*.toml` by `load_robot_config`, strictly (see `schema`), then
cross-checked against the URDF (joint names, order and the manufacturer's limits).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from orccadd.config.cellnet import load_cellnet
from orccadd.config.schema import field, format_range, load_dataclass
from orccadd.errors import ConfigError
from orccadd.wire.commands import LOAD_TIMEOUT_MAX_S

INF = math.inf


@dataclass(frozen=True)
class ModelConfig:
    """Where the dynamic model comes from.

    `urdf` is a path relative to the config file, or `example-robot-data:<path>` for a URDF
    shipped by the example-robot-data package. Joints of the URDF that the config does not list
    must be named in `locked_joints` (they are fixed at `locked_positions`, default 0).
    `armature_kg_m2` is each joint's reflected rotor inertia (rotor inertia × gear ratio²),
    which URDFs leave out but which dominates the wrist joints of real arms.
    """

    urdf: str = field(doc="URDF path")
    locked_joints: tuple[str, ...] = field(default=())
    locked_positions: tuple[float, ...] = field(default=())
    armature_kg_m2: tuple[float, ...] = field(default=(), bounds=(0.0, 100.0))


@dataclass(frozen=True)
class JointConfig:
    """One actuated joint and the limits the controller enforces (SI units, radians)."""

    name: str = field()
    position_min_rad: float = field()
    position_max_rad: float = field()
    max_velocity_rad_s: float = field(bounds=(0.0, INF), open_lo=True)
    max_acceleration_rad_s2: float = field(bounds=(0.0, INF), open_lo=True)
    max_jerk_rad_s3: float = field(bounds=(0.0, INF), open_lo=True)
    max_torque_nm: float = field(bounds=(0.0, INF), open_lo=True)
    home_rad: float = field(default=0.0)


@dataclass(frozen=True)
class SafeStopConfig:
    """What `safe_stop()` does (IEC 60204-1 stop categories).

    0: torque off and brakes at once; 1: controlled deceleration then torque off and brakes;
    2: controlled deceleration then hold position with torque on.
    """

    category: Literal[0, 1, 2] = field(default=1)
    deceleration_rad_s2: float = field(default=5.0, bounds=(0.0, INF), open_lo=True)
    timeout_s: float = field(default=2.0, bounds=(0.0, 60.0), open_lo=True)


@dataclass(frozen=True)
class LimitsConfig:
    """How the resource layer reacts to limits.

    Measured positions beyond the range by more than `position_tolerance_rad`, or speeds beyond
    `velocity_tolerance` times the maximum, raise a type 3 exception.
    """

    position_tolerance_rad: float = field(default=0.02, bounds=(0.0, 0.5))
    velocity_tolerance: float = field(default=1.1, bounds=(1.0, 2.0))


@dataclass(frozen=True)
class ToolConfig:
    """The tool the Cartesian tasks move (`[tool]`): a point fixed to a frame of the URDF.

    `frame` is a frame (link or fixed joint) of the URDF; "" is the link the last configured
    joint moves (the flange). `offset_m` and `offset_rpy_rad` place the tool's point and axes in
    that frame (roll, pitch, yaw about its fixed x, y, z). The limits bound every Cartesian
    motion of the tool (a task may go slower, never faster): by default 0.25 m/s, the reduced
    speed of ISO 10218-1 for a robot beside people.
    """

    frame: str = field(default="")
    offset_m: tuple[float, ...] = field(default=(0.0, 0.0, 0.0), bounds=(-2.0, 2.0))
    offset_rpy_rad: tuple[float, ...] = field(default=(0.0, 0.0, 0.0), bounds=(-math.pi, math.pi))
    max_linear_velocity_m_s: float = field(default=0.25, bounds=(0.0, 5.0), open_lo=True)
    max_linear_acceleration_m_s2: float = field(default=1.0, bounds=(0.0, 50.0), open_lo=True)
    max_linear_jerk_m_s3: float = field(default=10.0, bounds=(0.0, 5000.0), open_lo=True)
    max_angular_velocity_rad_s: float = field(default=1.0, bounds=(0.0, 10.0), open_lo=True)
    max_angular_acceleration_rad_s2: float = field(default=4.0, bounds=(0.0, 100.0), open_lo=True)
    max_angular_jerk_rad_s3: float = field(default=40.0, bounds=(0.0, 10000.0), open_lo=True)
    # the most a force task may ask the tool to push with (its setpoints are refused above)
    max_force_n: float = field(default=100.0, bounds=(0.0, 5000.0), open_lo=True)
    max_torque_nm: float = field(default=10.0, bounds=(0.0, 500.0), open_lo=True)


@dataclass(frozen=True)
class WorkspaceConfig:
    """Where the tool's point must stay (`[workspace]`), in the base frame: inside the box
    `box_min_m`..`box_max_m` and the sphere of `sphere_radius_m` about `sphere_center_m` (each
    left out when not given). Measured beyond it by more than `tolerance_m` is the type 3
    exception `LimitViolation` on any task (the arm stops as beyond a joint's range, whose
    `limits.position_tolerance_rad` this is the tool's counterpart of); a position command that
    would take the tool out of it is not sent (the last one is held) and is a `LimitViolation`
    too; a line's goal outside it is refused before the line starts."""

    box_min_m: tuple[float, ...] = field(default=(), bounds=(-20.0, 20.0))
    box_max_m: tuple[float, ...] = field(default=(), bounds=(-20.0, 20.0))
    sphere_center_m: tuple[float, ...] = field(default=(), bounds=(-20.0, 20.0))
    sphere_radius_m: float = field(default=0.0, bounds=(0.0, 20.0))
    tolerance_m: float = field(default=0.01, bounds=(0.0, 0.5))

    @property
    def given(self) -> bool:
        """Whether a box or a sphere is configured."""
        return bool(self.box_min_m) or self.sphere_radius_m > 0.0


@dataclass(frozen=True)
class DaemonConfig:
    """How `orccadd` runs this robot: socket, access roles, priorities, fault policies.

    The socket's directory gets mode 0750 and the socket 0660, both owned by `socket_group`
    (empty: the daemon's own group). A peer is allowed the control role if its uid is root or
    the daemon's, or its user/group is listed in `control_users`/`control_groups`; the read-only
    role (status, monitor, events, params) likewise with `read_users`/`read_groups`.
    """

    socket: str = field(default="/run/orccadd/orccadd.sock")
    socket_group: str = field(default="")
    control_users: tuple[str, ...] = field(default=())
    control_groups: tuple[str, ...] = field(default=("orccadd",))
    read_users: tuple[str, ...] = field(default=())
    read_groups: tuple[str, ...] = field(default=("orccadd-ro",))
    hold_task: str = field(default="../tasks/hold.toml")
    # `load` reads missions from these directories only (relative to this file): a client may not
    # make the root daemon read, or echo a line of, any other file
    mission_dirs: tuple[str, ...] = field(default=("../missions",))
    # and the task files a mission names (`from "file.toml"`) from these, or from `mission_dirs`
    task_dirs: tuple[str, ...] = field(default=("../tasks",))
    # a `load` compiles and verifies in a process of its own, stopped after this long or when it
    # needs this much more memory than it took to start (the mission refused, saying which;
    # `orccadctl check` has no limit). One load at a time: these bound how long a load can keep
    # the next one waiting (docs/mission-language.md: what missions of which size cost)
    load_timeout_s: float = field(default=120.0, bounds=(1.0, LOAD_TIMEOUT_MAX_S))
    load_memory_mb: int = field(default=1024, bounds=(256, 1 << 20))
    # a mission compiled and verified before (the same text, task files and orccadd) is loaded
    # from this cache without compiling again (orccadd/daemon/compile_cache.py); the directory
    # (relative to this file), "": missions/ in systemd's CacheDirectory, else in
    # $XDG_CACHE_HOME/orccadd, else in ~/.cache/orccadd
    compile_cache: bool = field(default=True)
    compile_cache_dir: str = field(default="")
    # missions deployed from a workstation (`orccadctl deploy`: orccadd/daemon/deploy.py), checked
    # as `load` checks, stored by content here (relative to this file; "": deployments/ in
    # systemd's StateDirectory, else in $XDG_STATE_HOME/orccadd), the newest so many kept
    deploy_dir: str = field(default="")
    deployments_kept: int = field(default=100, bounds=(1, 100000))
    # full-rate CSV logs go here, created by the command daemon (never a path a client names);
    # "": `logs/` in the socket's directory
    log_dir: str = field(default="")
    # a log (its CSV and MCAP together) ends once this large: a log left running fills no disk
    log_max_mb: float = field(default=2048.0, bounds=(1.0, 1 << 20))
    # connections the command daemon serves at once, per role: read-only clients cannot take
    # the control clients' places; clients without a role are answered once and closed
    control_clients: int = field(default=16, bounds=(1, 1024))
    read_clients: int = field(default=32, bounds=(0, 1024))
    idle_timeout_s: float = field(default=600.0, bounds=(1.0, 86400.0))
    # a client that does not read what it is sent (a stream, a reply) for this long is cut off:
    # its connection aborted, its buffers and slot freed
    stall_timeout_s: float = field(default=10.0, bounds=(0.5, 600.0))
    control_priority: int = field(default=80, bounds=(0, 98))
    automaton_priority: int = field(default=90, bounds=(0, 99))
    overrun_limit: int = field(default=5, bounds=(1, 1000))
    switch_blend_s: float = field(default=0.02, bounds=(0.0, 1.0))
    on_command_daemon_loss: Literal["continue", "safe_stop"] = field(default="continue")
    watchdog_stale_periods: int = field(default=50, bounds=(2, 100000))
    # a mission's task that runs longer than this (its task file's `[task] timeout_s`, 0: this)
    # raises the type 3 `Timeout`: nothing waits forever unless its task file says `inf`
    task_timeout_s: float = field(default=300.0, bounds=(0.1, 86400.0))
    # how a task's law runs each tick: "compiled" (one generated function per task: the modules'
    # kernels with their values as locals, orccadd/task/compiled.py) or "interpreted" (each
    # module's update on its ports: for stepping through a module in a debugger); the commands
    # are the same, bit for bit
    tick: Literal["compiled", "interpreted"] = field(default="compiled")
    # where each resource's control loop runs: "threads" (a thread each in the real-time
    # process), "processes" (a process each, `orccadd.daemon.unitproc`: one interpreter per
    # clock domain, so that no resource's Python stalls another's tick; docs/architecture.md),
    # or "auto": processes for a station of several resources, a thread for one resource
    units: Literal["auto", "threads", "processes"] = field(default="auto")


@dataclass(frozen=True)
class ResourceConfig:
    """The Physical Resource backend (`sim`, later `canopen`, `dynamixel`, `ur_rtde`)."""

    backend: str = field()
    name: str = field(default="arm")
    settings: dict[str, Any] = field(default=None)  # type: ignore[assignment]


@dataclass(frozen=True)
class RobotConfig:
    """A whole robot: model, joints, resource, control period and safety policy."""

    name: str = field()
    control_period_s: float = field(bounds=(0.0001, 0.1))
    model: ModelConfig = field()
    joints: tuple[JointConfig, ...] = field(min_len=1)
    resource: ResourceConfig = field()
    safe_stop: SafeStopConfig = field(default=SafeStopConfig())
    limits: LimitsConfig = field(default=LimitsConfig())
    daemon: DaemonConfig = field(default=DaemonConfig())
    tool: ToolConfig = field(default=ToolConfig())
    workspace: WorkspaceConfig = field(default=WorkspaceConfig())
    cell: Any = field(default=None)  # `[cell]`: a `CellNetConfig` once loaded (None: no cell)
    source: str = ""  # the file it was loaded from (set by the loader)
    backend_settings: Any = None  # the backend's typed settings (set by the loader)

    @property
    def dof(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def resolve(self, path: str) -> Path:
        """A path from the config, relative to the config file's folder."""
        return (Path(self.source).parent / path).resolve()


MAX_TOML_BYTES = 1 << 20


def read_toml(path: Path) -> dict[str, Any]:
    """Read a TOML file, turning syntax errors into `ConfigError` naming the file and line."""
    try:
        with path.open("rb") as fh:
            data = fh.read(MAX_TOML_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(str(path), "", "file not found") from None
    except OSError as e:
        raise ConfigError(str(path), "", f"cannot be read: {e.strerror}") from None
    return parse_toml(data, str(path))


def parse_toml(data: bytes, source: str) -> dict[str, Any]:
    """TOML text read from `source` (a file's name, for errors) as a table; `ConfigError` if it
    is too large, not UTF-8 or not TOML."""
    if len(data) > MAX_TOML_BYTES:
        raise ConfigError(source, "", f"is larger than {MAX_TOML_BYTES} bytes: not a config")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except RecursionError:
        raise ConfigError(source, "", "nests arrays or tables too deeply to be read") from None
    except UnicodeDecodeError as e:
        raise ConfigError(
            source, "", f"is not UTF-8 text, so not TOML ({e.reason} at byte {e.start})"
        ) from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(source, "", f"is not valid TOML: {e}") from None


def read_robot_config(path: str | Path) -> RobotConfig:
    """Read and check a robot config's form: keys, types, bounds, joints (no backend, no URDF).

    `orccadd.robot.load_robot_config` adds the backend's settings and the model checks; this is
    all the command daemon needs (its `[daemon]` table). Not for a tick: reads a file.
    """
    file = str(path)
    raw = read_toml(Path(path))
    for key in ("source", "backend_settings"):
        if key in raw:
            raise ConfigError(file, key, "is not a known key")
    cfg = replace(load_dataclass(RobotConfig, raw, file), source=file)
    if cfg.cell is not None:
        cfg = replace(cfg, cell=load_cellnet(cfg.cell, file, cfg.name))
    _check_joints(cfg, file)
    return cfg


def _check_joints(cfg: RobotConfig, file: str) -> None:
    seen: set[str] = set()
    for i, j in enumerate(cfg.joints):
        key = f"joints[{i}]"
        if j.name in seen:
            raise ConfigError(file, f"{key}.name", f"(={j.name!r}) is listed twice")
        seen.add(j.name)
        if not j.position_min_rad < j.position_max_rad:
            raise ConfigError(
                file,
                f"{key}.position_max_rad",
                f"(={j.position_max_rad!r}) must be greater than position_min_rad (={j.position_min_rad!r})",
            )
        if not j.position_min_rad <= j.home_rad <= j.position_max_rad:
            rng = format_range(j.position_min_rad, j.position_max_rad, False, False)
            raise ConfigError(file, f"{key}.home_rad", f"(={j.home_rad!r}) must be in {rng}")
    if len(cfg.model.armature_kg_m2) not in (0, cfg.dof):
        raise ConfigError(
            file,
            "model.armature_kg_m2",
            f"has {len(cfg.model.armature_kg_m2)} entries, must have one per joint ({cfg.dof}) or none",
        )
    _check_tool(cfg, file)
    if len(cfg.model.locked_positions) not in (0, len(cfg.model.locked_joints)):
        raise ConfigError(
            file,
            "model.locked_positions",
            f"has {len(cfg.model.locked_positions)} entries, must have one per locked joint "
            f"({len(cfg.model.locked_joints)}) or none",
        )


def _check_tool(cfg: RobotConfig, file: str) -> None:
    """Vectors of three, and a workspace whose box is a box and whose sphere has a centre."""
    three = (
        ("tool.offset_m", cfg.tool.offset_m, False),
        ("tool.offset_rpy_rad", cfg.tool.offset_rpy_rad, False),
        ("workspace.box_min_m", cfg.workspace.box_min_m, True),
        ("workspace.box_max_m", cfg.workspace.box_max_m, True),
        ("workspace.sphere_center_m", cfg.workspace.sphere_center_m, True),
    )
    for key, values, optional in three:
        if len(values) != 3 and not (optional and not values):
            allowed = "3 numbers (x, y, z)" + (" or none" if optional else "")
            raise ConfigError(file, key, f"has {len(values)} entries, must have {allowed}")
    w = cfg.workspace
    if bool(w.box_min_m) != bool(w.box_max_m):
        given, missing = ("box_min_m", "box_max_m") if w.box_min_m else ("box_max_m", "box_min_m")
        raise ConfigError(
            file, f"workspace.{missing}", f"is missing: a box needs both corners ({given} is given)"
        )
    for i, (lo, hi) in enumerate(zip(w.box_min_m, w.box_max_m, strict=True)):
        if not lo < hi:
            raise ConfigError(
                file, "workspace.box_max_m", f"(={list(w.box_max_m)!r}) must exceed box_min_m at index {i}"
            )
    if bool(w.sphere_center_m) != (w.sphere_radius_m > 0.0):
        raise ConfigError(
            file,
            "workspace.sphere_radius_m",
            f"(={w.sphere_radius_m!r}): a sphere needs both sphere_center_m and a radius > 0",
        )
