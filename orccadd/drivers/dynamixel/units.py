"""Joint units from and to servo units, per joint (direction, offset, gear ratio, model).

    horn angle θ = k · (q − offset_rad), k = direction · gear_ratio
    Present Position = 2048 + θ · 4096 / 2π          (ticks; 2048 at the horn's centre)
    Present Velocity = k · dq / (0.229 rpm)           (0.229 rpm = 0.02398 rad/s per unit)
    joint torque     = k · Present Current · current unit · torque constant   (estimate)
                       (XL430: k · Present Load · 0.1 % · stall torque)

The torque constant is the model's stall torque over its stall current (`models`): the e-Manual
gives no other, and the current-to-torque line of a DC motor through its gear is only close to
linear, so the torque is an estimate. Conversions are exact inverses up to the servo's rounding.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from orccadd.drivers.dynamixel.models import RPM, ServoModel

TICKS_PER_REV = 4096
CENTER_TICKS = 2048
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV
VELOCITY_UNIT_RAD_S = 0.229 * RPM
LOAD_UNIT = 0.001  # Present Load: 0.1 % of the stall torque


@dataclass(frozen=True)
class JointUnits:
    """The conversions of one joint's servo."""

    direction: int  # +1 or -1
    gear_ratio: float  # horn turns per joint turn
    offset_rad: float  # the joint angle at the horn's centre (2048)
    model: ServoModel

    @property
    def k(self) -> float:
        return self.direction * self.gear_ratio

    @property
    def rad_per_tick(self) -> float:
        """Joint radians per Present Position tick (signed by the direction)."""
        return RAD_PER_TICK / self.k

    @property
    def rad_s_per_unit(self) -> float:
        """Joint rad/s per Present Velocity unit (0.229 rpm at the horn)."""
        return VELOCITY_UNIT_RAD_S / self.k

    @property
    def nm_per_unit(self) -> float:
        """Joint N·m per Present Current unit (XL430: per Present Load unit)."""
        m = self.model
        if m.has_current:
            return self.k * m.current_unit_a * m.torque_constant_nm_a
        return self.k * LOAD_UNIT * m.stall_torque_nm

    def q_rad(self, ticks: float) -> float:
        return self.offset_rad + (ticks - CENTER_TICKS) * self.rad_per_tick

    def ticks(self, q_rad: float) -> int:
        return round(CENTER_TICKS + (q_rad - self.offset_rad) / self.rad_per_tick)

    def dq_rad_s(self, units: float) -> float:
        return units * self.rad_s_per_unit

    def velocity_units(self, dq_rad_s: float) -> int:
        return round(dq_rad_s / self.rad_s_per_unit)

    def tau_nm(self, units: float) -> float:
        return units * self.nm_per_unit

    def current_units(self, tau_nm: float) -> int:
        return round(tau_nm / self.nm_per_unit)

    def tick_range(self, lo_rad: float, hi_rad: float) -> tuple[int, int]:
        """The ticks of a joint range, low first (the direction may swap its ends), rounded out."""
        a = CENTER_TICKS + (lo_rad - self.offset_rad) / self.rad_per_tick
        b = CENTER_TICKS + (hi_rad - self.offset_rad) / self.rad_per_tick
        return math.floor(min(a, b)), math.ceil(max(a, b))

    def velocity_limit_units(self, dq_max_rad_s: float) -> int:
        """Velocity Limit(44) for a joint speed, rounded up."""
        return math.ceil(abs(dq_max_rad_s / self.rad_s_per_unit))

    def current_limit_units(self, tau_max_nm: float) -> int:
        """Current Limit(38) for a joint torque, rounded up, within the model's largest."""
        if not self.model.has_current:
            return 0
        return min(self.model.current_limit_max, math.ceil(abs(tau_max_nm / self.nm_per_unit)))


def factors(units: Sequence[JointUnits]) -> tuple[list[float], list[float], list[float], list[float]]:
    """Per joint, as plain lists for the cyclic path: offset, rad/tick, rad/s per unit, N·m per unit."""
    return (
        [u.offset_rad for u in units],
        [u.rad_per_tick for u in units],
        [u.rad_s_per_unit for u in units],
        [u.nm_per_unit for u in units],
    )
