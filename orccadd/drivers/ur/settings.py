"""`[resource.settings]` of the `ur_rtde` backend."""

from __future__ import annotations

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
