"""Value types shared by every layer (standard library only): command modes, resource status
flags, lifecycle and task phases, and the interface a task file offers the procedure compiler.

They travel on the wire too (telemetry records hold `Status` and `Phase` as numbers), so the
wire schema re-exports them and the command daemon decodes them without loading a backend.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from pathlib import Path


class CommandMode(IntEnum):
    """What `write()` commands. CiA 402: CSP / CSV / CST; UR: servoJ / speedJ; Dynamixel: position /
    velocity / current."""

    POSITION = 1
    VELOCITY = 2
    TORQUE = 3


class Lifecycle(IntEnum):
    """Resource lifecycle (after ros2_control): unconfigured → inactive → active → finalized."""

    UNCONFIGURED = 0
    INACTIVE = 1
    ACTIVE = 2
    FINALIZED = 3


class Status(IntFlag):
    """Status flags of a resource's last read/write. `T3_MASK` flags are type 3 exceptions."""

    OK = 0
    CMD_CLAMPED = 1  # a command beyond a limit was clamped (torque saturation is only this)
    LIMIT_VIOLATION = 2  # measured state or a position/velocity command outside the limits
    FAULT = 4  # the device reports a fault (drive fault, protective stop, hardware error)
    COMM_LOST = 8  # a communication watchdog expired
    STOPPING = 16  # a safe stop is in progress: commands are ignored
    STOPPED = 32  # at rest after a safe stop (brakes engaged, or holding)
    TORQUE_OFF = 64  # no torque on the motors


# as plain ints: IntFlag arithmetic costs ~1 µs a call, too much for a tick
CMD_CLAMPED = int(Status.CMD_CLAMPED)
LIMIT_VIOLATION = int(Status.LIMIT_VIOLATION)
T3_MASK = int(Status.LIMIT_VIOLATION | Status.FAULT | Status.COMM_LOST)


class Phase(IntEnum):
    """Where a Robot-Task is. DONE and ABORTED keep running the law until the task is switched."""

    IDLE = 0
    PRE = 1  # waiting for preconditions (the resource holds its last command)
    RUN = 2
    DONE = 3  # postcondition emitted
    ABORTED = 4  # type 2 exception emitted
    FAULT = 5  # type 3 exception: safe stop under way, no command is sent
    PRE_FAILED = 6  # preconditions not met in time (type 2): the law never started


@dataclass(frozen=True)
class TaskInterface:
    """A task file as the procedure compiler sees it: resource, joints, modules and the events
    the file declares (the built-in type 3 exceptions every task has are not listed)."""

    source: str
    resource: str
    command: CommandMode
    joints: tuple[str, ...]
    modules: tuple[str, ...]
    has_post: bool
    has_pre: bool
    t2: tuple[str, ...]
    t3: tuple[str, ...]
    sync: tuple[str, ...]
    times_out: bool = True  # raises the type 3 `Timeout` after its `timeout_s` (TASK_TIMEOUT)


# Reads a task file's interface; raises an `OrccaddError` naming the file when it cannot.
TaskFileReader = Callable[[Path], TaskInterface]


# Type 3 exceptions every Robot-Task has, raised below the mission: by the resource (a limit
# violated, a device fault, a link lost), the executor (overruns in a row) and the task itself
# (its law raised an exception: a module's or a backend's bug, never a dead control loop).
BUILTIN_T3 = ("LimitViolation", "ResourceFault", "CommLost", "Overrun", "LawError")
# ... and the one a task with a finite `timeout_s` has: it ran that long without ending
TASK_TIMEOUT = "Timeout"
