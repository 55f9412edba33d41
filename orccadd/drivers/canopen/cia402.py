"""The CiA 402 (IEC 61800-7-201) power drive state machine, both sides of it.

`DriveStateMachine` is the drive's side (the simulated drives run it): controlword in,
state and statusword out, transitions numbered as in the standard's figure:

     0  start -> NOT READY TO SWITCH ON                   (automatic)
     1  NOT READY TO SWITCH ON -> SWITCH ON DISABLED       (automatic, self-test done)
     2  SWITCH ON DISABLED -> READY TO SWITCH ON           Shutdown
     3  READY TO SWITCH ON -> SWITCHED ON                  Switch on
     4  SWITCHED ON -> OPERATION ENABLED                   Enable operation
     5  OPERATION ENABLED -> SWITCHED ON                   Disable operation
     6  SWITCHED ON -> READY TO SWITCH ON                  Shutdown
     7  READY TO SWITCH ON -> SWITCH ON DISABLED           Disable voltage / Quick stop
     8  OPERATION ENABLED -> READY TO SWITCH ON            Shutdown
     9  OPERATION ENABLED -> SWITCH ON DISABLED            Disable voltage
    10  SWITCHED ON -> SWITCH ON DISABLED                  Disable voltage / Quick stop
    11  OPERATION ENABLED -> QUICK STOP ACTIVE             Quick stop
    12  QUICK STOP ACTIVE -> SWITCH ON DISABLED            quick stop done (option 1-4) / Disable voltage
    13  any -> FAULT REACTION ACTIVE                       a fault
    14  FAULT REACTION ACTIVE -> FAULT                     fault reaction done
    15  FAULT -> SWITCH ON DISABLED                        Fault reset (rising edge of bit 7)
    16  QUICK STOP ACTIVE -> OPERATION ENABLED             Enable operation (option 5-8)

`decode_state` and `command_towards` are the controller's side: what state a statusword
reports, and which controlword moves a drive one step towards OPERATION ENABLED (or towards
SWITCHED ON, where the startup parks the drives until the cyclic exchange runs); `step_towards`,
`step_quick_stop` and `step_fault_reset` take a whole arm's drives one cycle on, whatever bus
carries their controlwords (CANopen's RPDOs, EtherCAT's process data).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol


class State(IntEnum):
    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


# statusword (0x6041) bits 0-3, 5, 6 code the state: (mask, value) per state
STATE_CODES: dict[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x4F, 0x00),
    State.SWITCH_ON_DISABLED: (0x4F, 0x40),
    State.READY_TO_SWITCH_ON: (0x6F, 0x21),
    State.SWITCHED_ON: (0x6F, 0x23),
    State.OPERATION_ENABLED: (0x6F, 0x27),
    State.QUICK_STOP_ACTIVE: (0x6F, 0x07),
    State.FAULT_REACTION_ACTIVE: (0x4F, 0x0F),
    State.FAULT: (0x4F, 0x08),
}

# statusword bits beyond the state
SW_VOLTAGE_ENABLED = 1 << 4
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_FOLLOWING = 1 << 12  # cyclic modes: the drive follows the target value
SW_FOLLOWING_ERROR = 1 << 13

# controlword (0x6040) commands
CW_DISABLE_VOLTAGE = 0x00
CW_QUICK_STOP = 0x02
CW_SHUTDOWN = 0x06
CW_SWITCH_ON = 0x07  # also "disable operation" from OPERATION ENABLED
CW_ENABLE_OPERATION = 0x0F
CW_FAULT_RESET = 0x80

# modes of operation (0x6060 / 0x6061) this project drives
MODE_CSP = 8  # cyclic synchronous position
MODE_CSV = 9  # cyclic synchronous velocity
MODE_CST = 10  # cyclic synchronous torque


def decode_state(statusword: int) -> State:
    for state, (mask, value) in STATE_CODES.items():
        if statusword & mask == value:
            return state
    return State.NOT_READY_TO_SWITCH_ON  # bit patterns the standard leaves undefined


def state_bits(state: State) -> int:
    return STATE_CODES[state][1]


# target state -> state now -> controlword (the comments: the standard's transition numbers)
TOWARDS: dict[State, dict[State, int | None]] = {
    State.OPERATION_ENABLED: {
        State.NOT_READY_TO_SWITCH_ON: None,
        State.FAULT_REACTION_ACTIVE: None,
        State.FAULT: CW_FAULT_RESET,  # 15
        State.SWITCH_ON_DISABLED: CW_SHUTDOWN,  # 2
        State.READY_TO_SWITCH_ON: CW_SWITCH_ON,  # 3
        State.SWITCHED_ON: CW_ENABLE_OPERATION,  # 4
        State.OPERATION_ENABLED: CW_ENABLE_OPERATION,  # stay
        State.QUICK_STOP_ACTIVE: CW_DISABLE_VOLTAGE,  # 12
    },
    State.SWITCHED_ON: {  # powered, torque off: where the startup leaves a drive until SYNC runs
        State.NOT_READY_TO_SWITCH_ON: None,
        State.FAULT_REACTION_ACTIVE: None,
        State.FAULT: CW_FAULT_RESET,  # 15
        State.SWITCH_ON_DISABLED: CW_SHUTDOWN,  # 2
        State.READY_TO_SWITCH_ON: CW_SWITCH_ON,  # 3
        State.SWITCHED_ON: CW_SWITCH_ON,  # stay
        State.OPERATION_ENABLED: CW_SWITCH_ON,  # 5 (disable operation)
        State.QUICK_STOP_ACTIVE: CW_DISABLE_VOLTAGE,  # 12
    },
}


def command_towards(state: State, target: State = State.OPERATION_ENABLED) -> int | None:
    """The controlword that moves a drive in `state` one step towards `target` (OPERATION
    ENABLED or SWITCHED ON; None: wait, the drive moves on by itself). FAULT needs a rising
    edge of bit 7: send CW_DISABLE_VOLTAGE first when the last controlword already had it."""
    return TOWARDS[target][state]


def _is_shutdown(cw: int) -> bool:
    return cw & 0x87 == 0x06


def _is_switch_on(cw: int) -> bool:  # also "disable operation"
    return cw & 0x8F == 0x07


def _is_enable_operation(cw: int) -> bool:  # "switch on + enable operation" too
    return cw & 0x8F == 0x0F


def _is_disable_voltage(cw: int) -> bool:
    return cw & 0x82 == 0x00


def _is_quick_stop(cw: int) -> bool:
    return cw & 0x86 == 0x02


class DriveStateMachine:
    """The drive side. `quick_stop_option` is object 0x605A (1-4: end in SWITCH ON DISABLED once
    stopped; 5-8: stay in QUICK STOP ACTIVE; 0: coast, i.e. SWITCH ON DISABLED at once)."""

    def __init__(self, quick_stop_option: int = 2) -> None:
        self.quick_stop_option = quick_stop_option
        self.state = State.NOT_READY_TO_SWITCH_ON  # transition 0
        self.last_transition = 0
        self._cw = 0
        self.extra_bits = SW_REMOTE

    def boot(self) -> None:
        """Self-test done (transition 1)."""
        if self.state is State.NOT_READY_TO_SWITCH_ON:
            self._go(State.SWITCH_ON_DISABLED, 1)

    @property
    def statusword(self) -> int:
        s = self.state
        voltage = SW_VOLTAGE_ENABLED if s in _POWERED else 0
        return state_bits(s) | voltage | self.extra_bits

    @property
    def power_stage_on(self) -> bool:
        """Torque is applied (the motor is driven): OPERATION ENABLED, or stopping under control."""
        return self.state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)

    def controlword(self, cw: int) -> int | None:
        """Apply a controlword; returns the transition number taken (None: no transition)."""
        rising_reset = bool(cw & 0x80) and not self._cw & 0x80
        self._cw = cw
        s = self.state
        if s is State.FAULT:
            return self._go(State.SWITCH_ON_DISABLED, 15) if rising_reset else None
        if s in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE) or cw & 0x80:
            return None
        if s is State.SWITCH_ON_DISABLED:
            return self._go(State.READY_TO_SWITCH_ON, 2) if _is_shutdown(cw) else None
        if s is State.READY_TO_SWITCH_ON:
            if _is_disable_voltage(cw) or _is_quick_stop(cw):
                return self._go(State.SWITCH_ON_DISABLED, 7)
            if _is_switch_on(cw):
                return self._go(State.SWITCHED_ON, 3)
            if _is_enable_operation(cw):  # 3 then 4 in one step, as drives accept it
                self._go(State.SWITCHED_ON, 3)
                return self._go(State.OPERATION_ENABLED, 4)
            return None
        if s is State.SWITCHED_ON:
            if _is_disable_voltage(cw) or _is_quick_stop(cw):
                return self._go(State.SWITCH_ON_DISABLED, 10)
            if _is_shutdown(cw):
                return self._go(State.READY_TO_SWITCH_ON, 6)
            if _is_enable_operation(cw):
                return self._go(State.OPERATION_ENABLED, 4)
            return None
        if s is State.OPERATION_ENABLED:
            if _is_disable_voltage(cw):
                return self._go(State.SWITCH_ON_DISABLED, 9)
            if _is_quick_stop(cw):
                if self.quick_stop_option == 0:  # coast: the drive function is disabled at once
                    return self._go(State.SWITCH_ON_DISABLED, 9)
                return self._go(State.QUICK_STOP_ACTIVE, 11)
            if _is_shutdown(cw):
                return self._go(State.READY_TO_SWITCH_ON, 8)
            if _is_switch_on(cw):
                return self._go(State.SWITCHED_ON, 5)
            return None
        # QUICK STOP ACTIVE
        if _is_disable_voltage(cw):
            return self._go(State.SWITCH_ON_DISABLED, 12)
        if _is_enable_operation(cw) and self.quick_stop_option >= 5:
            return self._go(State.OPERATION_ENABLED, 16)
        return None

    def quick_stop_done(self) -> int | None:
        """The quick stop ramp reached standstill (transition 12 for options 1-4)."""
        if self.state is State.QUICK_STOP_ACTIVE and 1 <= self.quick_stop_option <= 4:
            return self._go(State.SWITCH_ON_DISABLED, 12)
        return None

    def fault(self) -> int | None:
        """A fault was detected (transition 13); no-op while already in fault handling."""
        if self.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return None
        return self._go(State.FAULT_REACTION_ACTIVE, 13)

    def fault_reaction_done(self) -> int | None:
        if self.state is State.FAULT_REACTION_ACTIVE:
            return self._go(State.FAULT, 14)
        return None

    def _go(self, state: State, transition: int) -> int:
        self.state = state
        self.last_transition = transition
        return transition


_POWERED = (
    State.READY_TO_SWITCH_ON,
    State.SWITCHED_ON,
    State.OPERATION_ENABLED,
    State.QUICK_STOP_ACTIVE,
    State.FAULT_REACTION_ACTIVE,
)


# the power stage on: the drive holds or moves the joint
POWERED = (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)


class DriveWords(Protocol):
    """A drive as the controller sees it: the state its last statusword showed, the controlword
    the next cycle sends."""

    state: State
    controlword: int


def step_towards(drives: Iterable[DriveWords], target: State) -> bool:
    """One cycle towards `target` (SWITCHED ON or OPERATION ENABLED) on every drive (transitions
    2, 3, 4 or 5, and 15 out of a fault). True once every drive is there."""
    there = True
    for d in drives:
        cw = command_towards(d.state, target)
        if cw == CW_FAULT_RESET and d.controlword == CW_FAULT_RESET:
            cw = CW_DISABLE_VOLTAGE  # for a rising edge next time
        if cw is not None:
            d.controlword = cw
        there = there and d.state is target
    return there


def step_quick_stop(drives: Iterable[DriveWords]) -> bool:
    """One cycle of quick stop (transition 11) on every enabled drive. True once every drive has
    its power stage off."""
    off = True
    for d in drives:
        # a drive asked to enable may be enabled already, its statusword saying so not yet here
        if d.state is State.OPERATION_ENABLED or d.controlword == CW_ENABLE_OPERATION:
            d.controlword = CW_QUICK_STOP
        off = off and d.state not in POWERED
    return off


def step_fault_reset(drives: Iterable[DriveWords]) -> bool:
    """One cycle of fault reset: a rising edge of bit 7 on every faulted drive (reset, then
    disable voltage, then reset again). True once no drive is in FAULT."""
    done = True
    for d in drives:
        if d.state is State.FAULT:
            d.controlword = CW_FAULT_RESET if d.controlword != CW_FAULT_RESET else CW_DISABLE_VOLTAGE
            done = False
    return done


# error codes of EMCY messages and of 0x603F (CiA 301 / CiA 402) in words
ERROR_CODE_TEXTS = {
    0x2310: "over-current",
    0x3210: "DC link over-voltage",
    0x4310: "drive over-temperature",
    0x8110: "CAN overrun",
    0x8130: "heartbeat / life guard error",
    0x8611: "following error",
    0x7300: "sensor (encoder) error",
}


def error_code_text(code: int) -> str:
    """An error code in words ("" if unknown): exact, else its class (the high byte)."""
    return ERROR_CODE_TEXTS.get(code, ERROR_CODE_TEXTS.get(code & 0xFF00, ""))


@dataclass
class CycleReport:
    """What a master's cycle found wrong (its `receive`), for the resource's flags and words."""

    comm_lost: str = ""
    comm_lost_joint: str = ""  # the drive it is about ("" for the bus or line)
    fault: str = ""
    fault_joint: str = ""
    fault_code: int = 0
