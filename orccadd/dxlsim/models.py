"""The servo models the simulator knows: what ping answers and what the motor can do.

Figures from the ROBOTIS e-Manual pages of each model (Specifications and Control Table,
emanual.robotis.com/docs/en/dxl/x/xm430-w350/ and …/xm540-w270/): model number, stall torque
and current and no-load speed at 12 V, current unit, Current Limit and Velocity Limit defaults.
The reflected rotor inertia and the gear friction are not published: they are this
simulator's estimates (a mechanical time constant of 10-15 ms, a few percent of stall torque to
back-drive), stated here so that nobody mistakes them for data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

RPM = 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class ServoModel:
    """One DYNAMIXEL X model: identity, control-table specifics, motor figures at 12 V."""

    name: str
    model_number: int
    firmware_version: int
    stall_torque_nm: float  # at the horn, at rated_voltage_v
    stall_current_a: float
    no_load_speed_rad_s: float  # at the horn, at rated_voltage_v
    current_limit_max: int  # Current Limit(38): default and largest value, in current units
    current_unit_a: float
    velocity_limit_default: int  # Velocity Limit(44), 0.229 rpm units
    drive_mode_bits: int  # the Drive Mode(10) bits this model has (bit 1: dual joint, X540)
    rotor_inertia_kg_m2: float  # reflected to the horn (estimate)
    friction_nm: float  # Coulomb friction of the gear train at the horn (estimate)
    rated_voltage_v: float = 12.0

    @property
    def torque_constant_nm_a(self) -> float:
        return self.stall_torque_nm / self.stall_current_a


MODELS: dict[str, ServoModel] = {
    m.name: m
    for m in (
        ServoModel(
            name="XM430-W350",
            model_number=1020,
            firmware_version=46,
            stall_torque_nm=4.1,
            stall_current_a=2.3,
            no_load_speed_rad_s=46 * RPM,
            current_limit_max=1193,
            current_unit_a=0.00269,
            velocity_limit_default=200,
            drive_mode_bits=0x0D,
            rotor_inertia_kg_m2=0.012,
            friction_nm=0.08,
        ),
        ServoModel(
            name="XM540-W270",
            model_number=1120,
            firmware_version=46,
            stall_torque_nm=10.6,
            stall_current_a=4.4,
            no_load_speed_rad_s=30 * RPM,
            current_limit_max=2047,
            current_unit_a=0.00269,
            velocity_limit_default=128,
            drive_mode_bits=0x0F,
            rotor_inertia_kg_m2=0.03,
            friction_nm=0.2,
        ),
    )
}
