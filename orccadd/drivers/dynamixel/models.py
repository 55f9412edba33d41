"""The DYNAMIXEL X models this backend knows: identity, units and motor figures.

From the ROBOTIS e-Manual pages of each model (emanual.robotis.com/docs/en/dxl/x/<model>/:
Specifications and Control Table): the model number ping answers, the stall torque and current
at the rated voltage (their ratio is the torque constant the backend estimates torque with),
the no-load speed, the unit of Present/Goal Current and the largest Current Limit(38), the
operating modes. The XL430-W250 measures no current: Present Load(126) in 0.1 % of its stall
torque instead, and it has no current modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

RPM = 2.0 * math.pi / 60.0

# Operating Mode(11) values (e-Manual, Operating Mode)
CURRENT, VELOCITY, POSITION, EXTENDED_POSITION, CURRENT_BASED_POSITION, PWM = 0, 1, 3, 4, 5, 16
MODE_NAMES = {
    "current": CURRENT,
    "velocity": VELOCITY,
    "position": POSITION,
    "extended_position": EXTENDED_POSITION,
    "current_based_position": CURRENT_BASED_POSITION,
}
POSITION_MODES = (POSITION, EXTENDED_POSITION, CURRENT_BASED_POSITION)
ALL_MODES = frozenset({CURRENT, VELOCITY, POSITION, EXTENDED_POSITION, CURRENT_BASED_POSITION, PWM})
XL_MODES = frozenset({VELOCITY, POSITION, EXTENDED_POSITION, PWM})  # no current sensing


@dataclass(frozen=True)
class ServoModel:
    """One model. `current_unit_a` 0: no current sensing (torque from Present Load instead)."""

    name: str
    model_number: int
    stall_torque_nm: float  # at the horn, at rated_voltage_v
    stall_current_a: float
    no_load_speed_rad_s: float
    rated_voltage_v: float
    current_unit_a: float  # Present Current(126) / Goal Current(102) unit; 0: not measured
    current_limit_max: int  # largest Current Limit(38); 0: no such item
    modes: frozenset[int]  # the Operating Mode values it accepts

    @property
    def torque_constant_nm_a(self) -> float:
        """Stall torque over stall current (N·m/A): how current becomes a torque estimate."""
        return self.stall_torque_nm / self.stall_current_a

    @property
    def has_current(self) -> bool:
        return self.current_unit_a > 0.0


MODELS: dict[str, ServoModel] = {
    m.name: m
    for m in (
        ServoModel("XM430-W350", 1020, 4.1, 2.3, 46 * RPM, 12.0, 0.00269, 1193, ALL_MODES),
        ServoModel("XM540-W270", 1120, 10.6, 4.4, 30 * RPM, 12.0, 0.00269, 2047, ALL_MODES),
        ServoModel("XH430-W350", 1010, 3.4, 1.3, 30 * RPM, 12.0, 0.00134, 648, ALL_MODES),
        ServoModel("XL430-W250", 1060, 1.5, 1.4, 61 * RPM, 12.0, 0.0, 0, XL_MODES),
    )
}
BY_NUMBER: dict[int, ServoModel] = {m.model_number: m for m in MODELS.values()}


def model_name(model_number: int) -> str:
    """`XM430-W350 (1020)`, or `model number 1234 (not one this backend knows)`."""
    m = BY_NUMBER.get(model_number)
    return f"{m.name} ({model_number})" if m else f"model number {model_number} (not one this backend knows)"
