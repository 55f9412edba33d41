"""The control-table items this backend reads and writes (X series, Protocol 2.0).

Addresses and sizes from the e-Manual control tables (XM430-W350, XM540-W270, XH430-W350,
XL430-W250: the same layout; the XL430 has Present Load at 126 where the others have Present
Current, and no Current Limit(38) or Goal Current(102)). EEPROM is below 64: written only with
Torque Enable(64) at 0. Values are little-endian; signed where the e-Manual gives a negative
range.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Item:
    name: str
    address: int
    size: int  # bytes
    signed: bool = False

    @property
    def eeprom(self) -> bool:
        return self.address < 64

    def encode(self, value: int) -> list[int]:
        """The item's bytes, as the SDK's group classes take them (a list of ints)."""
        return list(int(value).to_bytes(self.size, "little", signed=self.signed))

    def decode(self, data: bytes | bytearray | list[int], offset: int = 0) -> int:
        return int.from_bytes(bytes(data[offset : offset + self.size]), "little", signed=self.signed)

    def __str__(self) -> str:
        return f"{self.name}({self.address})"


MODEL_NUMBER = Item("Model Number", 0, 2)
FIRMWARE_VERSION = Item("Firmware Version", 6, 1)
RETURN_DELAY_TIME = Item("Return Delay Time", 9, 1)  # 2 µs units
DRIVE_MODE = Item("Drive Mode", 10, 1)
OPERATING_MODE = Item("Operating Mode", 11, 1)
HOMING_OFFSET = Item("Homing Offset", 20, 4, signed=True)
CURRENT_LIMIT = Item("Current Limit", 38, 2)
VELOCITY_LIMIT = Item("Velocity Limit", 44, 4)
MAX_POSITION_LIMIT = Item("Max Position Limit", 48, 4)
MIN_POSITION_LIMIT = Item("Min Position Limit", 52, 4)
EEPROM_END = 64

TORQUE_ENABLE = Item("Torque Enable", 64, 1)
STATUS_RETURN_LEVEL = Item("Status Return Level", 68, 1)
HARDWARE_ERROR_STATUS = Item("Hardware Error Status", 70, 1)
POSITION_D_GAIN = Item("Position D Gain", 80, 2)
POSITION_I_GAIN = Item("Position I Gain", 82, 2)
POSITION_P_GAIN = Item("Position P Gain", 84, 2)
BUS_WATCHDOG = Item("Bus Watchdog", 98, 1, signed=True)  # 20 ms units; -1: it expired
GOAL_CURRENT = Item("Goal Current", 102, 2, signed=True)
GOAL_VELOCITY = Item("Goal Velocity", 104, 4, signed=True)
PROFILE_ACCELERATION = Item("Profile Acceleration", 108, 4)
PROFILE_VELOCITY = Item("Profile Velocity", 112, 4)
GOAL_POSITION = Item("Goal Position", 116, 4, signed=True)
PRESENT_CURRENT = Item("Present Current", 126, 2, signed=True)  # XL430: Present Load (0.1 %)
PRESENT_VELOCITY = Item("Present Velocity", 128, 4, signed=True)
PRESENT_POSITION = Item("Present Position", 132, 4, signed=True)

# The cyclic read: Present Current (or Load), Velocity and Position, one block of 10 bytes.
CYCLIC_START = PRESENT_CURRENT.address
CYCLIC_LENGTH = PRESENT_POSITION.address + PRESENT_POSITION.size - CYCLIC_START

# Baud Rate(8) values the X series accept within this backend's range, and the SDK's port
BAUD_RATES_BIT_S = (57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000)

BUS_WATCHDOG_UNIT_S = 0.02
RETURN_DELAY_UNIT_S = 2e-6
