"""`[resource.settings]` of the `dynamixel` backend: the port, the servos, the bus's watchdogs.

    [resource.settings]
    port = "/dev/ttyUSB0"            # the chain's serial device (U2D2, or the simulator's link)
    baud_rate = 4000000              # every servo's Baud Rate(8): 57600, 115200, 1M, 2M, 3M, 4M
    read_timeout_s = 0.003           # a status packet later than its wire time plus this: timeout
    comm_errors_in_a_row = 5         # failed cyclic reads (timeouts, CRC) in a row: CommLost
    fast_sync_read = true            # one status packet for the chain (firmware 45 and up: checked
                                     # at startup, a plain sync read where a servo has older)
    set_latency_timer = false        # a USB adapter's latency timer above 1 ms: refused (false) or
                                     # written down to 1 ms at startup (true: needs root)
    bus_watchdog_ms = 100            # velocity and current modes: the servos stop if we go silent
    torque_off_at_rest = false       # safe stop category 1 switches torque off at rest (no brakes!)
    reboot_timeout_s = 1.0           # reset: how long a rebooted servo may stay silent
    [[resource.settings.servos]]     # one per joint, in joint order
    id = 1                           # ID(7)
    model = "XM540-W270"             # ping must answer its model number
    direction = 1                    # +1: the joint turns with the servo's positive (CCW) sense
    offset_rad = 0.0                 # the joint angle at Present Position 2048
    gear_ratio = 1.0                 # horn turns per joint turn
    operating_mode = "position"      # position | extended_position | current_based_position |
                                     # velocity | current: written at configure; position
                                     # commands use it if it is a position mode
    position_p_gain = 800            # optional: Position P/I/D Gain(84/82/80), written at
    position_i_gain = 100            # every enable (absent: the servo's own)

Every check is here, before anything is opened: one servo per joint, ids once each, a rate the
servos have, the model able to run the mode, a joint range that position mode (one horn turn,
ticks 0-4095) can reach, category 1 only when torque off at rest is declared safe, and a read
timeout that fits the period.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from orccadd.config.robot import RobotConfig
from orccadd.config.schema import field, load_dataclass
from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel import wire
from orccadd.drivers.dynamixel.models import MODE_NAMES, MODELS, POSITION
from orccadd.drivers.dynamixel.units import TICKS_PER_REV, JointUnits
from orccadd.errors import ConfigError

KEY = "resource.settings"
OperatingMode = Literal["position", "extended_position", "current_based_position", "velocity", "current"]


@dataclass(frozen=True)
class ServoConfig:
    id: int = field(bounds=(0, 252))
    model: str = field(choices=tuple(MODELS))
    direction: Literal[1, -1] = field(default=1)
    offset_rad: float = field(default=0.0, bounds=(-100.0, 100.0))
    gear_ratio: float = field(default=1.0, bounds=(0.0, 1000.0), open_lo=True)
    operating_mode: OperatingMode = field(default="position")
    # the position loop's PID gains (RAM: written at every enable, a reboot resets them); absent:
    # the servo's own (P 800, I 0, D 0 on the X series: a joint sags by load / stiffness)
    position_p_gain: int | None = field(default=None, bounds=(0, 16383))
    position_i_gain: int | None = field(default=None, bounds=(0, 16383))
    position_d_gain: int | None = field(default=None, bounds=(0, 16383))

    def position_gains(self) -> list[tuple[T.Item, int]]:
        """The configured gains, as the items to write."""
        gains = (
            (T.POSITION_P_GAIN, self.position_p_gain),
            (T.POSITION_I_GAIN, self.position_i_gain),
            (T.POSITION_D_GAIN, self.position_d_gain),
        )
        return [(item, v) for item, v in gains if v is not None]


@dataclass(frozen=True)
class DynamixelSettings:
    port: str = field()
    servos: tuple[ServoConfig, ...] = field(min_len=1)
    baud_rate: int = field(default=1_000_000, bounds=(57_600, 4_000_000))
    read_timeout_s: float = field(default=0.003, bounds=(0.0002, 0.1))
    comm_errors_in_a_row: int = field(default=5, bounds=(1, 1000))
    fast_sync_read: bool = field(default=True)
    # the USB adapter's latency timer above 1 ms: written down to 1 ms at startup (needs write
    # access to sysfs: root) rather than refused
    set_latency_timer: bool = field(default=False)
    bus_watchdog_ms: int = field(default=100, bounds=(0, 2540))
    torque_off_at_rest: bool = field(default=False)
    reboot_timeout_s: float = field(default=1.0, bounds=(0.05, 30.0))
    # each servo's Return Delay Time(9), written with the torque off at startup: its wait before
    # answering. The factory's 500 µs costs six servos 3 ms a cycle; 0 is what a loop wants.
    return_delay_us: int = field(default=0, bounds=(0, 508))

    @property
    def n(self) -> int:
        return len(self.servos)

    def units(self) -> list[JointUnits]:
        return [JointUnits(s.direction, s.gear_ratio, s.offset_rad, MODELS[s.model]) for s in self.servos]

    def read_time_s(self) -> float:
        """The cyclic read's wire time: Present Current/Load, Velocity, Position of every servo,
        each answering after its Return Delay Time (`return_delay_us`, written at startup)."""
        delay_s = self.return_delay_us * 1e-6
        return wire.read_time_s(self.n, T.CYCLIC_LENGTH, self.baud_rate, delay_s, self.fast_sync_read)

    def write_time_s(self) -> float:
        """The cyclic write's wire time: the longest goal (Goal Position or Velocity, 4 bytes)."""
        return wire.write_time_s(self.n, T.GOAL_POSITION.size, self.baud_rate)

    @property
    def has_current(self) -> bool:
        """Every servo measures current (and so can run current modes)."""
        return all(MODELS[s.model].has_current for s in self.servos)


def load_dynamixel_settings(raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> DynamixelSettings:
    s = load_dataclass(DynamixelSettings, raw, file, KEY)
    if s.return_delay_us % 2:
        raise ConfigError(file, f"{KEY}.return_delay_us", f"(={s.return_delay_us}) must be even (2 µs units)")
    if s.baud_rate not in T.BAUD_RATES_BIT_S:
        rates = ", ".join(str(b) for b in T.BAUD_RATES_BIT_S)
        raise ConfigError(file, f"{KEY}.baud_rate", f"(={s.baud_rate!r}) must be one of {rates}")
    if len(s.servos) != len(cfg.joints):
        raise ConfigError(
            file, f"{KEY}.servos", f"has {len(s.servos)} entries, must have one per joint ({len(cfg.joints)})"
        )
    seen: set[int] = set()
    for i, (servo, units, joint) in enumerate(zip(s.servos, s.units(), cfg.joints, strict=True)):
        key = f"{KEY}.servos[{i}]"
        if servo.id in seen:
            raise ConfigError(file, f"{key}.id", f"(={servo.id}) is used twice")
        seen.add(servo.id)
        model = MODELS[servo.model]
        if MODE_NAMES[servo.operating_mode] not in model.modes:
            raise ConfigError(
                file,
                f"{key}.operating_mode",
                f"(={servo.operating_mode!r}) is not a mode of the {model.name} (servo {servo.id})",
            )
        if MODE_NAMES[servo.operating_mode] == POSITION:
            lo, hi = units.tick_range(joint.position_min_rad, joint.position_max_rad)
            if lo < 0 or hi > TICKS_PER_REV - 1:
                raise ConfigError(
                    file,
                    f"{key}.operating_mode",
                    f"(='position') cannot reach joint {joint.name}'s range "
                    f"[{joint.position_min_rad:g}, {joint.position_max_rad:g}] rad: it is ticks "
                    f"[{lo}, {hi}] of servo {servo.id}, position mode has 0-{TICKS_PER_REV - 1}; "
                    "use 'extended_position' or move offset_rad",
                )
    if cfg.safe_stop.category == 1 and not s.torque_off_at_rest:
        raise ConfigError(
            file,
            "safe_stop.category",
            "(=1) ends with the servos' torque off, and DYNAMIXEL servos have no brakes: an arm "
            "loaded by gravity falls. Use 2 (decelerate, then hold), or set "
            f"{KEY}.torque_off_at_rest = true if the arm rests safely unpowered",
        )
    busy = s.read_time_s() + s.write_time_s()
    # a period shorter than `busy` alone is check_description's to refuse (from describe)
    if busy <= cfg.control_period_s < busy + s.read_timeout_s:
        raise ConfigError(
            file,
            f"{KEY}.read_timeout_s",
            f"(={s.read_timeout_s:g}) plus the chain's read + write time ({busy * 1e3:.3g} ms at "
            f"{s.baud_rate} bit/s) must fit in control_period_s ({cfg.control_period_s:g})",
        )
    return s
