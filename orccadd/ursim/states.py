"""The controller's states as the RTDE guide and the dashboard server name them.

Numbers are UR's: `robot_mode`, `safety_mode`/`safety_status`, `runtime_state` and `joint_mode`
values, and the bits of `robot_status_bits` and `safety_status_bits` (RTDE guide, "Field names
and associated types"; the same enumerations in UR's client library, `ur/datatypes.h`).

The robot mode moves by a table of (mode, event) -> mode, like a real arm's power sequence:
power on boots the joints (POWER_ON) and leaves them braked (IDLE); brake release runs them
(RUNNING); power off, from anywhere, ends in POWER_OFF.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag

# the controller's words, defined once for the backend and the simulator
from orccadd.drivers.ur.controller import RobotMode as RobotMode
from orccadd.drivers.ur.controller import RuntimeState as RuntimeState
from orccadd.drivers.ur.controller import SafetyMode as SafetyMode


class JointMode(IntEnum):
    """`joint_mode` (one per joint)."""

    BACKDRIVE = 238
    POWER_OFF = 239
    BOOTING = 247
    FAULT = 252
    RUNNING = 253
    IDLE = 255


class RobotStatus(IntFlag):
    """`robot_status_bits`."""

    POWER_ON = 1 << 0
    PROGRAM_RUNNING = 1 << 1
    TEACH_BUTTON_PRESSED = 1 << 2
    POWER_BUTTON_PRESSED = 1 << 3


class SafetyStatus(IntFlag):
    """`safety_status_bits`."""

    NORMAL_MODE = 1 << 0
    REDUCED_MODE = 1 << 1
    PROTECTIVE_STOPPED = 1 << 2
    RECOVERY_MODE = 1 << 3
    SAFEGUARD_STOPPED = 1 << 4
    SYSTEM_EMERGENCY_STOPPED = 1 << 5
    ROBOT_EMERGENCY_STOPPED = 1 << 6
    EMERGENCY_STOPPED = 1 << 7
    VIOLATION = 1 << 8
    FAULT = 1 << 9
    STOPPED_DUE_TO_SAFETY = 1 << 10


SAFETY_BITS: dict[SafetyMode, SafetyStatus] = {
    SafetyMode.NORMAL: SafetyStatus.NORMAL_MODE,
    SafetyMode.REDUCED: SafetyStatus.REDUCED_MODE,
    SafetyMode.PROTECTIVE_STOP: SafetyStatus.PROTECTIVE_STOPPED | SafetyStatus.STOPPED_DUE_TO_SAFETY,
    SafetyMode.RECOVERY: SafetyStatus.RECOVERY_MODE,
    SafetyMode.SAFEGUARD_STOP: SafetyStatus.SAFEGUARD_STOPPED | SafetyStatus.STOPPED_DUE_TO_SAFETY,
    SafetyMode.SYSTEM_EMERGENCY_STOP: SafetyStatus.SYSTEM_EMERGENCY_STOPPED
    | SafetyStatus.EMERGENCY_STOPPED
    | SafetyStatus.STOPPED_DUE_TO_SAFETY,
    SafetyMode.ROBOT_EMERGENCY_STOP: SafetyStatus.ROBOT_EMERGENCY_STOPPED
    | SafetyStatus.EMERGENCY_STOPPED
    | SafetyStatus.STOPPED_DUE_TO_SAFETY,
    SafetyMode.VIOLATION: SafetyStatus.VIOLATION | SafetyStatus.STOPPED_DUE_TO_SAFETY,
    SafetyMode.FAULT: SafetyStatus.FAULT | SafetyStatus.STOPPED_DUE_TO_SAFETY,
}


class PowerEvent(IntEnum):
    """What moves the robot mode: dashboard commands, and the end of a timed step."""

    POWER_ON = 0
    BRAKE_RELEASE = 1
    POWER_OFF = 2
    BOOTED = 3  # the joints finished booting (POWER_ON lasts `BOOT_S`)
    RELEASED = 4  # the brakes opened (`RELEASE_S` after a brake release in IDLE)


# (mode, event) -> next mode. Events not listed leave the mode as it is.
POWER_TRANSITIONS: dict[tuple[RobotMode, PowerEvent], RobotMode] = {
    (RobotMode.POWER_OFF, PowerEvent.POWER_ON): RobotMode.POWER_ON,
    # an e-Series "brake release" from power off powers on first, then releases
    (RobotMode.POWER_OFF, PowerEvent.BRAKE_RELEASE): RobotMode.POWER_ON,
    # a brake release while booting is taken: the brakes open once the joints have booted
    (RobotMode.POWER_ON, PowerEvent.BRAKE_RELEASE): RobotMode.POWER_ON,
    (RobotMode.POWER_ON, PowerEvent.BOOTED): RobotMode.IDLE,
    (RobotMode.IDLE, PowerEvent.BRAKE_RELEASE): RobotMode.IDLE,  # releasing: RUNNING at RELEASED
    (RobotMode.IDLE, PowerEvent.RELEASED): RobotMode.RUNNING,
    (RobotMode.POWER_ON, PowerEvent.POWER_OFF): RobotMode.POWER_OFF,
    (RobotMode.IDLE, PowerEvent.POWER_OFF): RobotMode.POWER_OFF,
    (RobotMode.RUNNING, PowerEvent.POWER_OFF): RobotMode.POWER_OFF,
}

BOOT_S = 0.3  # POWER_ON -> IDLE (a real arm takes seconds; tests should not)
RELEASE_S = 0.2  # brake release -> RUNNING
UNLOCK_DELAY_S = 5.0  # a protective stop may be unlocked this long after it occurred (UR)
