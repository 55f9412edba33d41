"""What a Physical Resource declares about itself, and the config-time checks that follow.

A backend states, from its config alone and before anything is opened: its command modes and
whether switching between them needs the motors disabled, which quantities it measures,
estimates (from what) or lacks, whether it has brakes, which stop categories it can do, how
long a read and a write take on its bus, who paces the control loop (our executor, or the
device's own cycle), and which optional interfaces it offers (fault reset, fault injection).
`check_description` then refuses, with the file, key and value, what the declaration rules out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from orccadd.config.robot import RobotConfig
from orccadd.errors import ConfigError
from orccadd.types import CommandMode


class Source(Enum):
    MEASURED = "measured"
    ESTIMATED = "estimated"
    ABSENT = "absent"


@dataclass(frozen=True)
class Quantity:
    """How a resource knows one quantity: measured by a sensor, estimated (from `basis`), absent."""

    source: Source
    basis: str = ""  # for an estimate: from what ("motor current × torque constant")

    def describe(self) -> str:
        return f"{self.source.value} ({self.basis})" if self.basis else self.source.value


MEASURED = Quantity(Source.MEASURED)
ABSENT = Quantity(Source.ABSENT)


@dataclass(frozen=True)
class Signal:
    """A measured signal beyond the joint state (the flange's wrench, the speed slider): an
    output of the resource's node in every task's wiring (`arm.wrench`), filled by `read`."""

    name: str
    size: int
    unit: str
    what: str

    def describe(self) -> str:
        return f"{self.name} [{self.size}, {self.unit}]: {self.what}"


def tick_signals(signals: tuple[Signal, ...]) -> tuple[tuple[str, int], ...]:
    """The signals as the telemetry's tick record carries them (`orccadd.wire.schema.TickLayout`)."""
    return tuple((s.name, s.size) for s in signals)


class ClockSource(Enum):
    LOOP = "loop"  # our executor's absolute deadlines release each tick
    DEVICE = "device"  # the device's own cycle (a packet stream) releases each tick


@dataclass(frozen=True)
class ResourceDescription:
    """A backend's declaration (see the module docstring). Times in seconds."""

    backend: str
    joints: tuple[str, ...]
    modes: frozenset[CommandMode]
    mode_switch_needs_disable: bool
    position: Quantity
    velocity: Quantity
    torque: Quantity
    brakes: bool
    stop_categories: frozenset[int]
    read_time_s: float  # nominal duration of one read() on the bus
    write_time_s: float  # nominal duration of one write()
    clock: ClockSource = ClockSource.LOOP
    device_period_s: float = 0.0  # the device's cycle when it paces the loop (0: unknown until connect)
    fault_reset: bool = False  # `reset_fault()` asks the device to leave a fault
    fault_injection: tuple[str, ...] = ()  # kinds `inject_fault()` accepts
    extra: dict[str, str] = field(default_factory=dict)  # backend facts shown by `describe`
    signals: tuple[Signal, ...] = ()  # measured beyond q, dq, tau (task wiring outputs)
    # commanded beyond the joint command (optional task wiring inputs: a UR's force mode); a
    # task's module writes the tick's time in element 0 of those it commands in that tick
    commands: tuple[Signal, ...] = ()
    # named digital inputs (a mission's input `R.X` on each rising edge) and output actions (a
    # mission's `emit R.Y`), as the robot config names them
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, object]:
        """Plain data for `describe` and `status`."""
        return {
            "backend": self.backend,
            "modes": sorted(m.name.lower() for m in self.modes),
            "mode_switch_needs_disable": self.mode_switch_needs_disable,
            "position": self.position.describe(),
            "velocity": self.velocity.describe(),
            "torque": self.torque.describe(),
            "brakes": self.brakes,
            "stop_categories": sorted(self.stop_categories),
            "read_time_s": self.read_time_s,
            "write_time_s": self.write_time_s,
            "clock": self.clock.value,
            "device_period_s": self.device_period_s,
            "fault_reset": self.fault_reset,
            "fault_injection": list(self.fault_injection),
            "signals": [s.describe() for s in self.signals],
            # where they lie in each tick's telemetry record, after the joint vectors
            "tick_signals": [{"name": s.name, "size": s.size, "unit": s.unit} for s in self.signals],
            "commands": [s.describe() for s in self.commands],
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            **self.extra,
        }


def check_description(cfg: RobotConfig, d: ResourceDescription, *, gravity_loaded: bool) -> None:
    """Refuse a config the resource cannot serve. `gravity_loaded`: some joint holds a load
    against gravity at rest (from the model), so a stop without brakes lets the arm fall."""
    file, period = cfg.source, cfg.control_period_s
    busy = d.read_time_s + d.write_time_s
    if period < busy:
        raise ConfigError(
            file,
            "control_period_s",
            f"(={period:g}) must be at least the {d.backend} resource's read + write time "
            f"({d.read_time_s:g} + {d.write_time_s:g} s)",
        )
    if d.clock is ClockSource.DEVICE and d.device_period_s and abs(period - d.device_period_s) > 1e-9:
        raise ConfigError(
            file,
            "control_period_s",
            f"(={period:g}) must equal the device's cycle ({d.device_period_s:g} s): "
            f"the {d.backend} device paces the loop",
        )
    cat = cfg.safe_stop.category
    if cat not in d.stop_categories:
        allowed = ", ".join(str(c) for c in sorted(d.stop_categories))
        raise ConfigError(
            file,
            "safe_stop.category",
            f"(={cat}) must be one of {allowed} (what the {d.backend} resource can do)",
        )
    if cat == 0 and not d.brakes and gravity_loaded:
        raise ConfigError(
            file,
            "safe_stop.category",
            f"(=0) would drop the arm: the {d.backend} resource has no brakes and the arm is "
            "loaded by gravity; use category 1 or 2 (decelerate, then hold)",
        )
