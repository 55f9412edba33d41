"""The UR controller's state words (RTDE guide, "robot_mode", "safety_mode", "safety_status_bits",
"robot_status_bits", "runtime_state") and what each means for a controller on top of it.

Every tick the backend reads them; `condition()` names what stops the arm (a type 3 exception) and
whether a dashboard command can recover it (`reset`), or only a person at the pendant.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import IntEnum


class RobotMode(IntEnum):
    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(IntEnum):
    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13


class RuntimeState(IntEnum):
    STOPPING = 0
    STOPPED = 1
    PLAYING = 2
    PAUSING = 3
    PAUSED = 4
    RESUMING = 5


# safety_status_bits (RTDE guide)
SAFETY_BITS = (
    "normal", "reduced", "protective stopped", "recovery", "safeguard stopped",
    "system emergency stopped", "robot emergency stopped", "emergency stopped", "violation",
    "fault", "stopped due to safety",
)  # fmt: skip
ROBOT_POWER_ON = 1 << 0  # robot_status_bits
ROBOT_PROGRAM_RUNNING = 1 << 1

# how each safety mode is left: by a dashboard command (after the controller's wait), by itself
# once its cause is gone, or only at the pendant
RECOVERY = {
    SafetyMode.NORMAL: "",
    SafetyMode.REDUCED: "",
    SafetyMode.PROTECTIVE_STOP: "unlock",
    SafetyMode.SAFEGUARD_STOP: "clears when the safeguard input is reset",
    SafetyMode.AUTOMATIC_MODE_SAFEGUARD_STOP: "clears when the safeguard input is reset",
    SafetyMode.SYSTEM_THREE_POSITION_ENABLING_STOP: "clears when the enabling device is held",
    SafetyMode.RECOVERY: "pendant: move the arm back inside its limits in recovery mode",
    SafetyMode.SYSTEM_EMERGENCY_STOP: "pendant: release the emergency stop button",
    SafetyMode.ROBOT_EMERGENCY_STOP: "pendant: release the emergency stop button",
    SafetyMode.VIOLATION: "pendant: restart the safety system",
    SafetyMode.FAULT: "pendant: restart the safety system",
    SafetyMode.VALIDATE_JOINT_ID: "pendant: validate the joint ids",
    SafetyMode.UNDEFINED_SAFETY_MODE: "pendant",
}


@dataclass(frozen=True)
class Condition:
    """What stops the arm: `what` in words, and how it is recovered ("" if `reset` can)."""

    what: str
    unlockable: bool  # a protective stop: `unlock protective stop` (the controller allows it 5 s after)
    needs: str  # what a person must do, when no command can recover it


def condition(
    robot_mode: int, safety_mode: int, runtime_state: int, script_running: bool
) -> Condition | None:
    """The condition that stops the arm, or None when it may move."""
    if safety_mode not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
        known = safety_mode in SafetyMode._value2member_map_
        how = RECOVERY.get(SafetyMode(safety_mode), "pendant") if known else "pendant"
        what = f"safety mode {_name(SafetyMode, safety_mode)}"
        return Condition(what, how == "unlock", "" if how == "unlock" else how)
    if robot_mode != RobotMode.RUNNING:
        return Condition(
            f"robot mode {_name(RobotMode, robot_mode)}", False, "power on and release the brakes"
        )
    if not script_running:
        state = _name(RuntimeState, runtime_state)
        return Condition(f"the control script is not running (program {state})", False, "")
    return None


def _name(enum: type[IntEnum], value: int) -> str:
    return enum(value).name if value in enum._value2member_map_ else f"#{value}"


def safety_bits_text(bits: int) -> str:
    return ", ".join(n for i, n in enumerate(SAFETY_BITS) if bits >> i & 1) or "none"


@dataclass(frozen=True)
class Version:
    major: int
    minor: int
    bugfix: int
    build: int

    @property
    def e_series(self) -> bool:
        return self.major >= 5

    @property
    def period_s(self) -> float:
        """The controller's cycle, the RTDE stream's rate: 500 Hz (e-Series), 125 Hz (CB3)."""
        return 0.002 if self.e_series else 0.008

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}.{self.bugfix}.{self.build}"


def parse_polyscope_version(reply: str) -> Version:
    """`URSoftware 5.26.0.0 (Jan 01 2026)` (dashboard `PolyscopeVersion`) -> Version."""
    m = re.search(r"(\d+)\.(\d+)(?:\.(\d+))?(?:\.(\d+))?", reply)
    if m is None:
        raise ValueError(f"not a PolyscopeVersion reply: {reply!r}")
    return Version(int(m[1]), int(m[2]), int(m[3] or 0), int(m[4] or 0))


def robot_model_name(reply: str, version: Version) -> str:
    """Dashboard `get robot model` says UR3/UR5/UR10/UR16/UR20...; an e-Series arm is `UR5e`."""
    base = reply.strip().upper()
    if not re.fullmatch(r"UR\d+", base):
        raise ValueError(f"not a robot model reply: {reply!r}")
    return f"{base}e" if version.e_series and base in ("UR3", "UR5", "UR10", "UR16") else base
