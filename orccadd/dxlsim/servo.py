"""One simulated DYNAMIXEL X servo: its control table, its instructions, its faults.

What the servo does with its motor (control loops, the motor's torque-speed line) is in
`loop`; here is what it does with the bus and with its table:

- instructions on its own table: read, write, reg write/action, factory reset, reboot, clear,
  with the e-Manual's access rules (`table`) and the limits that depend on other items (Goal
  Position within the position limits in position mode, Goal Velocity/Current/PWM within their
  limits: Data Limit Error, 6); goals are read-only after a Bus Watchdog error (Data Range, 4);
- hardware errors (Hardware Error Status(70), the conditions enabled in Shutdown(63)): input
  voltage (bit 0), overheating (2), electrical shock (4), overload (5). One shuts the torque off
  and stays latched, with the alert bit in every status packet, until a reboot;
- power: unplugged (no answer, no torque), and the boot after a replug, a reboot or a factory
  reset (RAM at its power-on values, no answer for `BOOT_TIME_S`).

Choices where the e-Manual says nothing (stated so that nobody takes them for the hardware's):
at power-up Goal Position is the present position, and switching torque on keeps Goal Position,
so a servo moved by hand while off heads back to it (a controller must write Goal Position =
Present Position before torque on); writing Torque Enable 1 while an error is latched is
refused with Result Fail (1); a factory reset with torque on is refused with Access Error (7).
Not simulated: indirect addresses, Drive Mode bit 3 (torque on by goal update), the dual-joint
bit of the XM540 (accepted, no effect), the external ports.
"""

from __future__ import annotations

from orccadd.dxlsim import table as T
from orccadd.dxlsim.loop import ServoLoop
from orccadd.dxlsim.models import ServoModel
from orccadd.dxlsim.protocol import ALERT, Error

BOOT_TIME_S = 0.2  # no answer this long after power-up or a reboot (estimate)
MODES = (0, 1, 3, 4, 5, 16)  # current, velocity, position, extended position, current-based position, PWM
GOALS = (T.GOAL_PWM, T.GOAL_CURRENT, T.GOAL_VELOCITY, T.GOAL_POSITION)
VOLTAGE_ERROR, OVERHEATING, ENCODER, ELECTRICAL_SHOCK, OVERLOAD = 0x01, 0x04, 0x08, 0x10, 0x20
CLEAR_MULTI_TURN = bytes((0x01, 0x44, 0x58, 0x4C, 0x22))
RESET_ALL, RESET_EXCEPT_ID, RESET_EXCEPT_ID_BAUD = 0xFF, 0x01, 0x02


class Servo:
    """A servo on the chain. Times are the simulator's clock (seconds)."""

    def __init__(self, model: ServoModel, dxl_id: int, baud_index: int) -> None:
        self.model = model
        self.table = T.ControlTable()
        T.factory_defaults(self.table, model, dxl_id, baud_index)
        self.loop = ServoLoop(model, self.table)
        self.plugged = True
        self.awake_at_s = 0.0
        self.registered: tuple[int, bytes] | None = None
        self.held_temperature_c: float | None = None  # an injected overheating holds it

    # ---- identity and reachability --------------------------------------------------------
    @property
    def dxl_id(self) -> int:
        return self.table.get(T.ID)

    @property
    def secondary_id(self) -> int:
        return self.table.get(T.SECONDARY_ID)

    def hears(self, line_baud: int, now_s: float) -> bool:
        """Whether it can take a packet now: powered, booted, at the line's speed, Protocol 2.0."""
        return (
            self.plugged
            and now_s >= self.awake_at_s
            and T.BAUD_RATES_BIT_S[self.table.get(T.BAUD_RATE)] == line_baud
            and self.table.get(T.PROTOCOL_TYPE) == 2
        )

    @property
    def return_delay_s(self) -> float:
        return 2e-6 * self.table.get(T.RETURN_DELAY_TIME)

    @property
    def status_return_level(self) -> int:
        return self.table.get(T.STATUS_RETURN_LEVEL)

    def error_byte(self, error: Error) -> int:
        return int(error) | (ALERT if self.table.get(T.HARDWARE_ERROR_STATUS) else 0)

    # ---- instructions ---------------------------------------------------------------------
    @property
    def firmware(self) -> int:
        return self.table.get(T.FIRMWARE_VERSION)

    def ping(self) -> bytes:
        return T.encode(T.MODEL_NUMBER, self.model.model_number) + bytes((self.firmware,))

    def read(self, address: int, length: int, now_s: float) -> bytes | Error:
        if address + length > T.REALTIME_TICK.address:
            self.loop.refresh(now_s)
        return self.table.read(address, length)

    def write(self, address: int, data: bytes, now_s: float) -> Error:
        checked = self._check_write(address, data)
        if isinstance(checked, Error):
            return checked
        for item, value in checked:
            self._apply(item, value, now_s)
        return Error.NONE

    def reg_write(self, address: int, data: bytes) -> Error:
        checked = self._check_write(address, data)
        if isinstance(checked, Error):
            return checked
        self.registered = (address, data)
        self.table.set(T.REGISTERED_INSTRUCTION, 1)
        return Error.NONE

    def action(self, now_s: float) -> Error:
        if self.registered is None:
            return Error.INSTRUCTION
        address, data = self.registered
        self.registered = None
        self.table.set(T.REGISTERED_INSTRUCTION, 0)
        return self.write(address, data, now_s)

    def factory_reset(self, option: int, now_s: float) -> Error:
        if option not in (RESET_ALL, RESET_EXCEPT_ID, RESET_EXCEPT_ID_BAUD):
            return Error.DATA_RANGE
        if self.table.get(T.TORQUE_ENABLE):
            return Error.ACCESS
        dxl_id = 1 if option == RESET_ALL else self.dxl_id
        baud = self.table.get(T.BAUD_RATE) if option == RESET_EXCEPT_ID_BAUD else 1
        T.factory_defaults(self.table, self.model, dxl_id, baud)
        self.boot(now_s)
        return Error.NONE

    def clear(self, params: bytes) -> Error:
        if params != CLEAR_MULTI_TURN:
            return Error.DATA_RANGE
        if self.loop.moving:
            return Error.RESULT_FAIL
        self.loop.clear_turns()
        return Error.NONE

    # ---- power ----------------------------------------------------------------------------
    def boot(self, now_s: float) -> None:
        """Power-on: RAM at its power-on values, answering again after `BOOT_TIME_S`."""
        T.ram_defaults(self.table)
        self.registered = None
        self.awake_at_s = now_s + BOOT_TIME_S
        self.loop.boot()
        if self.table.get(T.STARTUP_CONFIGURATION) & 0x01:
            self._apply(T.TORQUE_ENABLE, 1, now_s)

    def unplug(self) -> None:
        self.plugged = False
        self.table.set(T.TORQUE_ENABLE, 0)
        self.loop.torque_off()

    def replug(self, now_s: float) -> None:
        if not self.plugged:
            self.plugged = True
            self.boot(now_s)

    # ---- faults ---------------------------------------------------------------------------
    def raise_hardware_error(self, bits: int) -> None:
        """A detected condition: latched and torque off if Shutdown(63) enables it."""
        bits &= self.table.get(T.SHUTDOWN)
        if bits:
            self.table.set(T.HARDWARE_ERROR_STATUS, self.table.get(T.HARDWARE_ERROR_STATUS) | bits)
            self.table.set(T.TORQUE_ENABLE, 0)
            self.loop.torque_off()

    def step(self, theta_rad: float, omega_rad_s: float, h_s: float, bus_idle_s: float) -> float:
        """One control period of `h_s` at horn angle `theta_rad` (servo's own sense, before Drive
        Mode): the torque the motor puts on the horn (N·m); faults detected on the way."""
        if not self.plugged:
            return 0.0
        watchdog = self.table.get(T.BUS_WATCHDOG)
        if watchdog > 0 and self.table.get(T.TORQUE_ENABLE) and bus_idle_s > 0.02 * watchdog:
            self.table.set(T.BUS_WATCHDOG, -1)
            self.loop.stop_here(theta_rad)
        torque = self.loop.step(theta_rad, omega_rad_s, h_s)
        if self.held_temperature_c is not None:
            self.loop.temperature_c = self.held_temperature_c
        errors = 0
        if self.loop.temperature_c > self.table.get(T.TEMPERATURE_LIMIT):
            errors |= OVERHEATING
        if self.loop.overloaded:
            errors |= OVERLOAD
        volts = self.table.get(T.PRESENT_INPUT_VOLTAGE)
        if not self.table.get(T.MIN_VOLTAGE_LIMIT) <= volts <= self.table.get(T.MAX_VOLTAGE_LIMIT):
            errors |= VOLTAGE_ERROR
        if errors & ~self.table.get(T.HARDWARE_ERROR_STATUS):
            self.raise_hardware_error(errors)
        return torque if self.table.get(T.TORQUE_ENABLE) else 0.0

    # ---- writes ---------------------------------------------------------------------------
    def _check_write(self, address: int, data: bytes) -> list[tuple[T.Item, int]] | Error:
        checked = self.table.decode_write(address, data, bool(self.table.get(T.TORQUE_ENABLE)))
        if isinstance(checked, Error):
            return checked
        for item, value in checked:
            error = self._check_value(item, value)
            if error:
                return error
        return checked

    def _check_value(self, item: T.Item, value: int) -> Error:
        t = self.table
        if item in GOALS and t.get(T.BUS_WATCHDOG) == -1:
            return Error.DATA_RANGE
        if item is T.OPERATING_MODE and value not in MODES:
            return Error.DATA_RANGE
        if item is T.DRIVE_MODE and value & ~self.model.drive_mode_bits:
            return Error.DATA_RANGE
        if item is T.CURRENT_LIMIT and value > self.model.current_limit_max:
            return Error.DATA_RANGE
        if item is T.SECONDARY_ID and 252 < value < 255:
            return Error.DATA_RANGE
        if item is T.TORQUE_ENABLE and value and t.get(T.HARDWARE_ERROR_STATUS):
            return Error.RESULT_FAIL
        limits = {
            T.GOAL_PWM: t.get(T.PWM_LIMIT),
            T.GOAL_CURRENT: t.get(T.CURRENT_LIMIT),
            T.GOAL_VELOCITY: t.get(T.VELOCITY_LIMIT),
        }
        if item in limits and abs(value) > limits[item]:
            return Error.DATA_LIMIT
        in_range = t.get(T.MIN_POSITION_LIMIT) <= value <= t.get(T.MAX_POSITION_LIMIT)
        if item is T.GOAL_POSITION and t.get(T.OPERATING_MODE) == 3 and not in_range:
            return Error.DATA_LIMIT
        return Error.NONE

    def _apply(self, item: T.Item, value: int, now_s: float) -> None:
        t = self.table
        if item is T.BUS_WATCHDOG and value == 0 and t.get(T.BUS_WATCHDOG) == -1:
            self.loop.watchdog_cleared()
        t.set(item, value)
        if item is T.TORQUE_ENABLE:
            if value:
                self.loop.torque_on()
            else:
                self.loop.torque_off()
        elif item is T.GOAL_POSITION:
            self.loop.goal_position_written()
        elif item is T.GOAL_VELOCITY:
            self.loop.goal_velocity_written()
