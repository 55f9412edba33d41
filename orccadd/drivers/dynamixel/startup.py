"""What the backend writes to the servos before it moves them (configure), and the operating
mode each servo takes for a command mode.

EEPROM (below address 64) is written only where it differs from what the config needs, and only
with the torque off (the servos refuse otherwise, and switching torque off would drop a loaded
arm: a servo left enabled whose EEPROM differs is refused, naming the items). The values:

- Return Delay Time(9) = 0: the servos answer at once (the default 250 = 0.5 ms per reply);
- Drive Mode(10) bits 0 and 2 cleared: the servo's own sense (the config's `direction` turns
  it), velocity-based profile (unused: Profile Velocity/Acceleration are 0, goals stream);
- Operating Mode(11): the configured one;
- Homing Offset(20) = 0: Present Position is the horn's, as `units` assumes;
- Min/Max Position Limit(52/48): the joint range in ticks (position mode refuses goals
  beyond; kept within one turn, 0-4095, where the range is wider: unused in the other modes);
- Velocity Limit(44): the joint's max velocity × the velocity tolerance, in 0.229 rpm;
- Current Limit(38): the joint's max torque through the torque constant, within the model's.
"""

from __future__ import annotations

from dataclasses import dataclass

from orccadd.config.robot import RobotConfig
from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel.models import (
    CURRENT,
    EXTENDED_POSITION,
    MODE_NAMES,
    MODELS,
    POSITION,
    POSITION_MODES,
    VELOCITY,
)
from orccadd.drivers.dynamixel.settings import DynamixelSettings
from orccadd.drivers.dynamixel.units import TICKS_PER_REV
from orccadd.types import CommandMode

VELOCITY_LIMIT_MAX = 1023
DRIVE_MODE_CLEARED = 0x05  # bit 0 reverse, bit 2 time-based profile


@dataclass(frozen=True)
class EepromTarget:
    """The EEPROM values one servo must hold (Drive Mode: the bits to clear)."""

    values: dict[T.Item, int]

    def differences(self, block: bytes) -> dict[T.Item, int]:
        """Items whose value in `block` (the servo's bytes 0-63) differs from the target,
        Drive Mode included (its bits to clear)."""
        out = {item: v for item, v in self.values.items() if item.decode(block, item.address) != v}
        drive = T.DRIVE_MODE.decode(block, T.DRIVE_MODE.address)
        if drive & DRIVE_MODE_CLEARED:
            out[T.DRIVE_MODE] = drive & ~DRIVE_MODE_CLEARED
        return out


def eeprom_targets(settings: DynamixelSettings, cfg: RobotConfig) -> list[EepromTarget]:
    out = []
    tol = cfg.limits.velocity_tolerance
    for servo, units, joint in zip(settings.servos, settings.units(), cfg.joints, strict=True):
        lo, hi = units.tick_range(joint.position_min_rad, joint.position_max_rad)
        values = {
            T.RETURN_DELAY_TIME: settings.return_delay_us // 2,  # 2 µs units
            T.OPERATING_MODE: MODE_NAMES[servo.operating_mode],
            T.HOMING_OFFSET: 0,
            T.MIN_POSITION_LIMIT: min(max(lo, 0), TICKS_PER_REV - 1),
            T.MAX_POSITION_LIMIT: min(max(hi, 0), TICKS_PER_REV - 1),
            T.VELOCITY_LIMIT: min(
                VELOCITY_LIMIT_MAX, units.velocity_limit_units(joint.max_velocity_rad_s * tol)
            ),
        }
        if MODELS[servo.model].has_current:
            values[T.CURRENT_LIMIT] = units.current_limit_units(joint.max_torque_nm)
        out.append(EepromTarget(values))
    return out


def operating_modes(settings: DynamixelSettings, cfg: RobotConfig, mode: CommandMode) -> list[int]:
    """Each servo's Operating Mode(11) for command `mode`: current (0), velocity (1), or for
    positions the configured position mode, else position (3) where the joint's range fits in
    one turn and extended position (4) where it does not."""
    if mode is CommandMode.TORQUE:
        return [CURRENT] * settings.n
    if mode is CommandMode.VELOCITY:
        return [VELOCITY] * settings.n
    out = []
    for servo, units, joint in zip(settings.servos, settings.units(), cfg.joints, strict=True):
        configured = MODE_NAMES[servo.operating_mode]
        if configured in POSITION_MODES:
            out.append(configured)
            continue
        lo, hi = units.tick_range(joint.position_min_rad, joint.position_max_rad)
        out.append(POSITION if lo >= 0 and hi <= TICKS_PER_REV - 1 else EXTENDED_POSITION)
    return out


def goal_item(mode: CommandMode) -> T.Item:
    """The goal a command mode streams."""
    if mode is CommandMode.POSITION:
        return T.GOAL_POSITION
    if mode is CommandMode.VELOCITY:
        return T.GOAL_VELOCITY
    return T.GOAL_CURRENT
