"""`[resource.settings]` of the `canopen402` backend: the bus, the drives, the PDO layout.

    [resource.settings]
    interface = "socketcan"        # a robot PC: the kernel's CAN (can0); tests: "socketcand"
    channel = "can0"
    bitrate_bit_s = 1000000
    mode = "csp"                   # csp | csv | cst, every axis
    heartbeat_ms = 100             # the drives' heartbeat; silent for 3 periods -> type 3
    controller_heartbeat_ms = 50   # ours; drives that can consume it fault after 3 periods
    [[resource.settings.axes]]     # one per joint, in joint order
    node_id = 1
    eds = "drives/elmo-gold.dcf"   # relative to this file, or found in $ORCCADD_EDS_PATH
    counts_per_rev = 4096
    gear_ratio = 100.0
    rated_torque_nm = 0.5          # the motor's rated torque (0x6076): torques are per mille of it
    # bus = "can1"                 # the bus it is on (default: the one above, `channel`)

More buses (a robot PC: one CAN interface each, can0 + can1; each carries its own SYNC, and its
own bus load is checked): a table per further bus, naming its channel and what differs from
the first bus (interface, host, port, bitrate_bit_s); axes name it by `bus`:

    [[resource.settings.buses]]
    channel = "can1"
    port = 29537                   # socketcand: a second host or port; SocketCAN: not needed

Node ids are unique per bus. One RPDO (controlword + the mode's target + the torque or position
target it may switch with) and one TPDO (statusword + position actual + torque actual) per axis,
8 bytes each, both synchronous: the layout the bus load is computed for (see `master`). Every
check happens here, before anything starts: axes per joint, node ids unique per bus, every axis
on a bus and every bus with an axis, descriptions found and able to do the mode, each bus's load
within 90 % (a refusal names the bus).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from orccadd.config.robot import RobotConfig
from orccadd.config.schema import field, load_dataclass
from orccadd.drivers.canopen.busload import Traffic, bus_load
from orccadd.drivers.canopen.capabilities import read_capabilities
from orccadd.errors import ConfigError


@dataclass(frozen=True)
class AxisConfig:
    node_id: int = field(bounds=(1, 127))
    eds: str = field()
    counts_per_rev: int = field(default=4096, bounds=(1, 2**31 - 1))
    gear_ratio: float = field(default=100.0, bounds=(0.0, 1e6), open_lo=True)
    rated_torque_nm: float = field(default=1.0, bounds=(0.0, 1e4), open_lo=True)
    bus: str = field(default="")  # the channel of the bus it is on; "": the first bus


@dataclass(frozen=True)
class BusConfig:
    """A further bus: its channel and what differs from the first bus's settings."""

    channel: str = field()
    interface: Literal["socketcan", "socketcand"] | None = field(default=None)
    host: str | None = field(default=None)
    port: int | None = field(default=None, bounds=(1, 65535))
    bitrate_bit_s: int | None = field(default=None, bounds=(10_000, 1_000_000))


@dataclass(frozen=True)
class Bus:
    """One bus, resolved: how to open it and which axes (indices in joint order) it carries."""

    interface: str
    channel: str
    host: str
    port: int
    bitrate_bit_s: int
    axes: tuple[int, ...]

    def bus_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of python-can's `can.Bus` for this bus."""
        if self.interface == "socketcand":
            # tcp_tune (TCP_NODELAY): a tick's SYNC and RPDOs leave at once, not held by Nagle's
            # algorithm until the server acknowledges the first frame
            tcp = {"host": self.host, "port": self.port, "tcp_tune": True}
            return {"interface": "socketcand", "channel": self.channel, **tcp}
        return {"interface": "socketcan", "channel": self.channel, "bitrate": self.bitrate_bit_s}

    def where(self) -> str:
        """The bus in messages: `can0`, or `can0 (socketcand 127.0.0.1:29536)`."""
        if self.interface == "socketcand":
            return f"{self.channel} (socketcand {self.host}:{self.port})"
        return self.channel


@dataclass(frozen=True)
class CanopenSettings:
    axes: tuple[AxisConfig, ...] = field(min_len=1)
    interface: Literal["socketcan", "socketcand"] = field(default="socketcan")
    channel: str = field(default="can0")
    host: str = field(default="127.0.0.1")
    port: int = field(default=29536, bounds=(1, 65535))
    bitrate_bit_s: int = field(default=1_000_000, bounds=(10_000, 1_000_000))
    mode: Literal["csp", "csv", "cst"] = field(default="csp")
    heartbeat_ms: int = field(default=100, bounds=(10, 10_000))
    controller_heartbeat_ms: int = field(default=50, bounds=(10, 10_000))
    missed_tpdo_periods: int = field(default=3, bounds=(1, 1000))
    # how long a tick may wait, from its release, for the TPDOs of the SYNC it sent last (every
    # bus's, gathered before it computes); 0: read what is there. Real drives answer within the
    # period (nothing to wait for); slow ones (simulated, behind a userspace bus) may need it.
    # Judged by the frames' time stamps: SocketCAN, or a socketcand server on this host
    tpdo_wait_us: int = field(default=0, bounds=(0, 100_000))
    # the worst-case bus load above which startup warns (above 90 % it refuses): an integrator
    # who has chosen a fuller bus says so here, once, instead of reading the warning at every start
    bus_load_warn: float = field(default=0.70, bounds=(0.1, 0.9))
    following_error_rad: float = field(default=0.1, bounds=(0.0, 10.0), open_lo=True)  # CSP, 0x6065
    following_error_timeout_ms: int = field(default=100, bounds=(0, 65535))  # 0x6066
    sdo_timeout_s: float = field(default=0.5, bounds=(0.01, 10.0))
    # how long a drive may take to show a new mode of operation (0x6061) once 0x6060 is written
    mode_display_timeout_s: float = field(default=0.5, bounds=(0.01, 10.0))
    startup_timeout_s: float = field(default=5.0, bounds=(0.1, 120.0))
    # the bus's I/O threads (canopen's receiver, the startup heartbeat producer) at SCHED_FIFO
    # (0: time-shared): below the control thread (daemon.control_priority, 80) and below the
    # simulated devices and bus hub of the tests (70), above anything time-shared. Time-shared,
    # they starved on a busy machine and the drives watching our heartbeat faulted (EMCY 0x8130)
    io_priority: int = field(default=65, bounds=(0, 98))
    emcy_type2_codes: tuple[int, ...] = field(default=(), bounds=(0, 0xFFFF))
    buses: tuple[BusConfig, ...] = field(default=())  # further buses (the first: the keys above)
    eds_paths: tuple[str, ...] = field(default=())  # resolved (absolute) by the loader

    def bus_list(self) -> list[Bus]:
        """Every bus, the first (this table's own keys) first, each with its axes."""
        out = [Bus(self.interface, self.channel, self.host, self.port, self.bitrate_bit_s, ())]
        for b in self.buses:
            out.append(
                Bus(
                    b.interface or self.interface,
                    b.channel,
                    self.host if b.host is None else b.host,
                    self.port if b.port is None else b.port,
                    b.bitrate_bit_s or self.bitrate_bit_s,
                    (),
                )
            )
        on: dict[str, list[int]] = {bus.channel: [] for bus in out}
        for i, ax in enumerate(self.axes):
            on.setdefault(ax.bus or self.channel, []).append(i)
        return [replace(bus, axes=tuple(on[bus.channel])) for bus in out]

    def bus_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of python-can's `can.Bus` for the first bus."""
        return self.bus_list()[0].bus_kwargs()

    def traffic(self, n: int | None = None) -> list[Traffic]:
        """One bus's frames with `n` axes on it (default: every axis)."""
        n = len(self.axes) if n is None else n
        return [
            Traffic("SYNC", 0),
            Traffic("RPDO", 8, per_cycle=n),  # controlword + the mode's target + its partner's
            Traffic("TPDO", 8, per_cycle=n),
            Traffic("drive heartbeats", 1, rate_hz=n * 1000 / self.heartbeat_ms),
            Traffic("controller heartbeat", 1, rate_hz=1000 / self.controller_heartbeat_ms),
        ]


def find_eds(name: str, cfg_dir: Path) -> Path | None:
    """`name` relative to the config's folder, else in the folders of $ORCCADD_EDS_PATH."""
    cands = [cfg_dir / name]
    for d in os.environ.get("ORCCADD_EDS_PATH", "").split(os.pathsep):
        if d:
            cands.append(Path(d) / name)
    for p in cands:
        try:
            if p.is_file():
                return p.resolve()
        except (OSError, ValueError):  # a name too long, a NUL: not found here
            continue
    return None


def load_canopen_settings(raw: Any, cfg: RobotConfig, file: str) -> CanopenSettings:
    s = load_dataclass(CanopenSettings, raw, file, "resource.settings")
    key = "resource.settings.axes"
    if len(s.axes) != cfg.dof:
        raise ConfigError(file, key, f"has {len(s.axes)} entries, must have one per joint ({cfg.dof})")
    paths = []
    for i, ax in enumerate(s.axes):
        path = find_eds(ax.eds, Path(file).parent)
        if path is None:
            raise ConfigError(
                file,
                f"{key}[{i}].eds",
                f"(={ax.eds!r}) not found next to the config nor in $ORCCADD_EDS_PATH",
            )
        try:
            caps = read_capabilities(path, ax.node_id)
        except Exception as e:  # whatever the canopen library raises on a broken description
            raise ConfigError(file, f"{key}[{i}].eds", f"(={ax.eds!r}) cannot be read: {e}") from None
        try:
            caps.require(s.mode)
        except ValueError as e:
            raise ConfigError(file, f"{key}[{i}] ({cfg.joints[i].name})", f"mode {s.mode!r}: {e}") from None
        if caps.hint_excludes(s.mode):
            print(
                f"{file}: warning: {key}[{i}]: {path.name} does not list {s.mode} in its supported drive "
                "modes (0x6502 default); the drive's own value is checked at startup",
                file=sys.stderr,
            )
        paths.append(str(path))
    _check_buses(s, file)
    if s.tpdo_wait_us * 1e-6 >= cfg.control_period_s / 2:
        raise ConfigError(
            file,
            "resource.settings.tpdo_wait_us",
            f"(={s.tpdo_wait_us}) must be below half the control period ({cfg.control_period_s * 5e5:g} µs)",
        )
    for bus in s.bus_list():
        load = bus_load(s.traffic(len(bus.axes)), cfg.control_period_s, bus.bitrate_bit_s)
        verdict, message = load.verdict(s.bus_load_warn)
        named = f"bus {bus.channel}: {message}"
        if verdict == "refuse":
            raise ConfigError(file, "control_period_s", f"(={cfg.control_period_s:g}): {named}")
        if verdict == "warn":
            print(f"{file}: warning: {named}", file=sys.stderr)
    return replace(s, eds_paths=tuple(paths))


def _check_buses(s: CanopenSettings, file: str) -> None:
    """Channels unique, every axis on a known bus, every bus with an axis, node ids unique per bus."""
    key = "resource.settings"
    channels = [s.channel]
    for i, b in enumerate(s.buses):
        if b.channel in channels:
            raise ConfigError(file, f"{key}.buses[{i}].channel", f"(={b.channel!r}) names a bus twice")
        channels.append(b.channel)
    seen: dict[tuple[str, int], int] = {}
    for i, ax in enumerate(s.axes):
        bus = ax.bus or s.channel
        if bus not in channels:
            raise ConfigError(
                file, f"{key}.axes[{i}].bus", f"(={ax.bus!r}) is no bus here (buses: {', '.join(channels)})"
            )
        if (bus, ax.node_id) in seen:
            other = seen[(bus, ax.node_id)]
            raise ConfigError(
                file, f"{key}.axes[{i}].node_id", f"(={ax.node_id}) is also axes[{other}]'s (bus {bus})"
            )
        seen[(bus, ax.node_id)] = i
    for carried in s.bus_list():
        if not carried.axes:
            raise ConfigError(
                file, f"{key}.buses", f"bus {carried.channel!r} carries no axis (set axes[].bus)"
            )
