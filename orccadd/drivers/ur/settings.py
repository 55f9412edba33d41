"""`[resource.settings]` of the `ur_rtde` backend."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from orccadd.config.schema import field

# The controller's bounds for servoJ (UR script manual): lookahead_time 0.03-0.2 s, gain 100-2000.
LOOKAHEAD_S = (0.03, 0.2)
GAIN = (100.0, 2000.0)
# each model's rated payload, kg (UR's data sheets)
RATED_PAYLOAD_KG = {
    "UR3e": 3.0, "UR5e": 5.0, "UR10e": 12.5, "UR16e": 16.0, "UR20": 20.0, "UR30": 30.0,
    "UR3": 3.0, "UR5": 5.0, "UR10": 10.0,
}  # fmt: skip


@dataclass(frozen=True)
class UrRtdeSettings:
    host: str = field()
    model: Literal["UR3e", "UR5e", "UR10e", "UR16e", "UR20", "UR30", "UR3", "UR5", "UR10"] = field(
        default="UR5e", doc="the arm the config describes; checked against the controller's"
    )
    min_version: str = field(default="5.4", doc="oldest controller software accepted (CB3: 3.15)")
    # servoJ: the controller smooths toward the target over `lookahead_time_s` (more: smoother,
    # and that much more delay) with proportional `gain` (more: stiffer, can oscillate)
    lookahead_time_s: float = field(default=0.1, bounds=LOOKAHEAD_S)
    gain: float = field(default=300.0, bounds=GAIN)
    speedj_acceleration_rad_s2: float = field(default=1.4, bounds=(0.01, 40.0))
    power_on: bool = field(default=False, doc="power on and release the brakes at startup")
    # ur_rtde's receive and control threads at SCHED_FIFO (0: time-shared): just below the
    # control thread (daemon.control_priority, 80), so the stream keeps up on a busy machine
    rtde_priority: int = field(default=79, bounds=(0, 98))
    # the controller's RTDE watchdog: no command from us for this long stops the control script
    # (and the arm), whatever became of this process
    watchdog_s: float = field(default=0.1, bounds=(0.01, 1.0))
    stall_periods: int = field(default=3, bounds=(2, 1000), doc="no packet for this many periods: CommLost")
    connect_timeout_s: float = field(default=10.0, bounds=(0.5, 120.0))
    # the tool, set on the controller each time the control script starts (none: the
    # installation's, as set at the pendant): its mass, its centre of gravity from the flange
    # (x, y, z in m), and the TCP from the flange (x, y, z in m, rotation vector in rad)
    payload_kg: float | None = field(default=None, bounds=(0.0, 35.0))
    payload_cog_m: list[float] | None = field(default=None)
    tcp_m_rad: list[float] | None = field(default=None)
    # named digital inputs, each a mission input `R.X` on its rising edge: the controller's DI0-DI7,
    # its configurable CI0-CI7, the tool's TI0-TI1 (`{ part_present = "DI0" }`)
    digital_inputs: dict[str, str] | None = field(default=None)
    # named output actions, each a mission's `emit R.Y`: an output set (=on) or cleared (=off),
    # the controller's DO0-DO7, its configurable CO0-CO7, the tool's TO0-TO1
    # (`{ close_gripper = "TO0=on", open_gripper = "TO0=off" }`)
    digital_outputs: dict[str, str] | None = field(default=None)
    # what a task may ask of the controller's force mode (`ur_force_mode`): the force it applies
    # (the wrench's force, N) and the speed of its compliant axes (m/s); more is a type 3, unsent
    force_mode_max_force_n: float = field(default=50.0, bounds=(0.0, 150.0))
    force_mode_max_speed_m_s: float = field(default=0.25, bounds=(0.0, 1.5))


IO_BANKS = {"D": (0, 8), "C": (8, 8), "T": (16, 2)}  # bank letter: first bit, count (RTDE's layout)
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def io_bit(spec: str, kind: str) -> int:
    """ "DI3" (kind "I") or "TO1" (kind "O") → its bit in RTDE's digital bits (standard 0-7,
    configurable 8-15, tool 16-17); ValueError with what is allowed."""
    m = re.fullmatch(rf"([DCT]){kind}(\d)", spec)
    if m is None or int(m[2]) >= IO_BANKS[m[1]][1]:
        raise ValueError(f"is not one of D{kind}0-D{kind}7, C{kind}0-C{kind}7, T{kind}0-T{kind}1")
    first, _ = IO_BANKS[m[1]]
    return first + int(m[2])


def output_action(spec: str) -> tuple[int, bool]:
    """ "TO0=on" → (bit 16, True)."""
    pin, _, level = spec.partition("=")
    if level not in ("on", "off"):
        raise ValueError("must be OUTPUT=on or OUTPUT=off (e.g. TO0=on)")
    return io_bit(pin, "O"), level == "on"
