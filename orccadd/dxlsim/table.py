"""The control table of a DYNAMIXEL X servo (XM430 / XM540, Protocol 2.0): layout and access.

Addresses, sizes, access and ranges from the e-Manual's control tables (XM430-W350,
XM540-W270). EEPROM is addresses 0-63, RAM 64 and up; EEPROM items can only be written with
Torque Enable(64) at 0. Values are little-endian, signed where the e-Manual gives negative
ranges. The table ends at Backup Ready(147): indirect addresses and data (168 and up) and the
XM540's external ports are not simulated (reading or writing them is an access error).

How a write is judged (e-Manual, Protocol 2.0, status packet errors), in this order:

- a byte outside every item, a read-only item, or an EEPROM item with torque on -> Access (7);
- an item only partly covered by the data -> Data Length (5);
- a value outside the item's fixed range -> Data Range (4).

Limits that depend on other items (Goal Position within the position limits, Goal Velocity
within Velocity Limit, …) are the servo's to check (`servo`). A read may span the gaps between
items; they read as 0.
"""

from __future__ import annotations

from dataclasses import dataclass

from orccadd.dxlsim.models import ServoModel
from orccadd.dxlsim.protocol import Error

I32 = (-(2**31), 2**31 - 1)


@dataclass(frozen=True, eq=False)
class Item:
    name: str
    address: int
    size: int
    writable: bool = True
    signed: bool = False
    lo: int = 0
    hi: int = 0  # 0 with lo 0: any value of the size

    @property
    def eeprom(self) -> bool:
        return self.address < 64

    @property
    def end(self) -> int:
        return self.address + self.size


def _ro(name: str, address: int, size: int, signed: bool = False) -> Item:
    return Item(name, address, size, writable=False, signed=signed)


MODEL_NUMBER = _ro("Model Number", 0, 2)
MODEL_INFORMATION = _ro("Model Information", 2, 4)
FIRMWARE_VERSION = _ro("Firmware Version", 6, 1)
ID = Item("ID", 7, 1, lo=0, hi=252)
BAUD_RATE = Item("Baud Rate", 8, 1, lo=0, hi=7)
RETURN_DELAY_TIME = Item("Return Delay Time", 9, 1, lo=0, hi=254)
DRIVE_MODE = Item("Drive Mode", 10, 1, lo=0, hi=15)  # the model's bits are checked by the servo
OPERATING_MODE = Item("Operating Mode", 11, 1, lo=0, hi=16)  # 0,1,3,4,5,16: checked by the servo
SECONDARY_ID = Item("Secondary ID", 12, 1, lo=0, hi=255)
PROTOCOL_TYPE = Item("Protocol Type", 13, 1, lo=1, hi=2)
HOMING_OFFSET = Item("Homing Offset", 20, 4, signed=True, lo=-1_044_479, hi=1_044_479)
MOVING_THRESHOLD = Item("Moving Threshold", 24, 4, lo=0, hi=1023)
TEMPERATURE_LIMIT = Item("Temperature Limit", 31, 1, lo=0, hi=100)
MAX_VOLTAGE_LIMIT = Item("Max Voltage Limit", 32, 2, lo=95, hi=160)
MIN_VOLTAGE_LIMIT = Item("Min Voltage Limit", 34, 2, lo=95, hi=160)
PWM_LIMIT = Item("PWM Limit", 36, 2, lo=0, hi=885)
CURRENT_LIMIT = Item("Current Limit", 38, 2, lo=0, hi=2047)  # the model's maximum: by the servo
VELOCITY_LIMIT = Item("Velocity Limit", 44, 4, lo=0, hi=1023)
MAX_POSITION_LIMIT = Item("Max Position Limit", 48, 4, lo=0, hi=4095)
MIN_POSITION_LIMIT = Item("Min Position Limit", 52, 4, lo=0, hi=4095)
STARTUP_CONFIGURATION = Item("Startup Configuration", 60, 1, lo=0, hi=3)
SHUTDOWN = Item("Shutdown", 63, 1, lo=0, hi=0x3D)

TORQUE_ENABLE = Item("Torque Enable", 64, 1, lo=0, hi=1)
LED = Item("LED", 65, 1, lo=0, hi=1)
STATUS_RETURN_LEVEL = Item("Status Return Level", 68, 1, lo=0, hi=2)
REGISTERED_INSTRUCTION = _ro("Registered Instruction", 69, 1)
HARDWARE_ERROR_STATUS = _ro("Hardware Error Status", 70, 1)
VELOCITY_I_GAIN = Item("Velocity I Gain", 76, 2, lo=0, hi=16383)
VELOCITY_P_GAIN = Item("Velocity P Gain", 78, 2, lo=0, hi=16383)
POSITION_D_GAIN = Item("Position D Gain", 80, 2, lo=0, hi=16383)
POSITION_I_GAIN = Item("Position I Gain", 82, 2, lo=0, hi=16383)
POSITION_P_GAIN = Item("Position P Gain", 84, 2, lo=0, hi=16383)
FEEDFORWARD_2ND_GAIN = Item("Feedforward 2nd Gain", 88, 2, lo=0, hi=16383)
FEEDFORWARD_1ST_GAIN = Item("Feedforward 1st Gain", 90, 2, lo=0, hi=16383)
BUS_WATCHDOG = Item("Bus Watchdog", 98, 1, signed=True, lo=0, hi=127)  # -1: watchdog error
GOAL_PWM = Item("Goal PWM", 100, 2, signed=True, lo=-885, hi=885)
GOAL_CURRENT = Item("Goal Current", 102, 2, signed=True, lo=-2047, hi=2047)
GOAL_VELOCITY = Item("Goal Velocity", 104, 4, signed=True, lo=-1023, hi=1023)
PROFILE_ACCELERATION = Item("Profile Acceleration", 108, 4, lo=0, hi=32767)
PROFILE_VELOCITY = Item("Profile Velocity", 112, 4, lo=0, hi=32767)
GOAL_POSITION = Item("Goal Position", 116, 4, signed=True, lo=-1_048_575, hi=1_048_575)
REALTIME_TICK = _ro("Realtime Tick", 120, 2)
MOVING = _ro("Moving", 122, 1)
MOVING_STATUS = _ro("Moving Status", 123, 1)
PRESENT_PWM = _ro("Present PWM", 124, 2, signed=True)
PRESENT_CURRENT = _ro("Present Current", 126, 2, signed=True)
PRESENT_VELOCITY = _ro("Present Velocity", 128, 4, signed=True)
PRESENT_POSITION = _ro("Present Position", 132, 4, signed=True)
VELOCITY_TRAJECTORY = _ro("Velocity Trajectory", 136, 4, signed=True)
POSITION_TRAJECTORY = _ro("Position Trajectory", 140, 4, signed=True)
PRESENT_INPUT_VOLTAGE = _ro("Present Input Voltage", 144, 2)
PRESENT_TEMPERATURE = _ro("Present Temperature", 146, 1)
BACKUP_READY = _ro("Backup Ready", 147, 1)

ITEMS: tuple[Item, ...] = tuple(v for v in list(globals().values()) if isinstance(v, Item))
TABLE_SIZE = max(item.end for item in ITEMS)
_AT: dict[int, Item] = {a: item for item in ITEMS for a in range(item.address, item.end)}

BAUD_RATES_BIT_S = (9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)


def encode(item: Item, value: int) -> bytes:
    return int(value).to_bytes(item.size, "little", signed=item.signed)


class ControlTable:
    """One servo's control table, with the e-Manual's access rules. The values are held as
    integers (the control loops read them every period); `read` lays them out as bytes."""

    def __init__(self) -> None:
        self.values: dict[Item, int] = dict.fromkeys(ITEMS, 0)

    def get(self, item: Item) -> int:
        return self.values[item]

    def set(self, item: Item, value: int) -> None:
        """Store `value` (the servo's own update: no access or range check; clipped to the size)."""
        bits = 8 * item.size
        if item.signed:
            lo, hi = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        else:
            lo, hi = 0, (1 << bits) - 1
        self.values[item] = min(max(int(value), lo), hi)

    def read(self, address: int, length: int) -> bytes | Error:
        """`length` bytes from `address`, or the error a servo would answer."""
        if length < 1:
            return Error.DATA_LENGTH
        end = address + length
        if end > TABLE_SIZE:
            return Error.ACCESS
        out = bytearray(length)
        for item in ITEMS:
            if item.address < end and item.end > address:
                raw = encode(item, self.values[item])
                lo, hi = max(item.address, address), min(item.end, end)
                out[lo - address : hi - address] = raw[lo - item.address : hi - item.address]
        return bytes(out)

    def decode_write(self, address: int, data: bytes, torque_on: bool) -> list[tuple[Item, int]] | Error:
        """The (item, value) pairs a write of `data` at `address` makes, or the error it earns."""
        if not data:
            return Error.DATA_LENGTH
        end = address + len(data)
        items: list[Item] = []
        for a in range(address, end):
            item = _AT.get(a)
            if item is None or not item.writable or (item.eeprom and torque_on):
                return Error.ACCESS
            if not items or items[-1] is not item:
                items.append(item)
        if items[0].address < address or items[-1].end > end:
            return Error.DATA_LENGTH
        out = []
        for item in items:
            value = int.from_bytes(
                data[item.address - address : item.end - address], "little", signed=item.signed
            )
            if (item.lo or item.hi) and not item.lo <= value <= item.hi:
                return Error.DATA_RANGE
            out.append((item, value))
        return out


def factory_defaults(table: ControlTable, model: ServoModel, dxl_id: int = 1, baud_index: int = 1) -> None:
    """Every item at its factory value (e-Manual "Default Value" column); RAM measurements 0."""
    for item in ITEMS:
        table.values[item] = 0
    for item, value in (
        (MODEL_NUMBER, model.model_number),
        (FIRMWARE_VERSION, model.firmware_version),
        (ID, dxl_id),
        (BAUD_RATE, baud_index),
        (RETURN_DELAY_TIME, 250),
        (OPERATING_MODE, 3),
        (SECONDARY_ID, 255),
        (PROTOCOL_TYPE, 2),
        (MOVING_THRESHOLD, 10),
        (TEMPERATURE_LIMIT, 80),
        (MAX_VOLTAGE_LIMIT, 160),
        (MIN_VOLTAGE_LIMIT, 95),
        (PWM_LIMIT, 885),
        (CURRENT_LIMIT, model.current_limit_max),
        (VELOCITY_LIMIT, model.velocity_limit_default),
        (MAX_POSITION_LIMIT, 4095),
        (SHUTDOWN, 52),
    ):
        table.set(item, value)
    ram_defaults(table)


def ram_defaults(table: ControlTable) -> None:
    """RAM items at their power-on values (a reboot); EEPROM untouched."""
    for item in ITEMS:
        if not item.eeprom:
            table.values[item] = 0
    for item, value in (
        (STATUS_RETURN_LEVEL, 2),
        (VELOCITY_I_GAIN, 1920),
        (VELOCITY_P_GAIN, 100),
        (POSITION_P_GAIN, 800),
        (GOAL_PWM, table.get(PWM_LIMIT)),
        (GOAL_CURRENT, table.get(CURRENT_LIMIT)),
        (PRESENT_INPUT_VOLTAGE, 120),
        (PRESENT_TEMPERATURE, 30),
    ):
        table.set(item, value)
