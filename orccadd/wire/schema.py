"""The telemetry block's layout and the enums decoded from it, and the protocol version.

The real-time process writes the block (`orccadd.wire.telemetry`), the command daemon reads it;
both take every index and enum from here. Values are float64 throughout (one numpy view per area):

- header: sizes, the writer's pid, a heartbeat (monotonic ns of the last tick), loop counters;
- status: the machine's state, under a sequence lock (odd while writing);
- tick ring: one record per control tick (`TICK_FIELDS`, then `TICK_VECTORS` one value per joint);
- trace ring: one record per automaton instant, task event or operator action.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from orccadd.types import CommandMode, Phase, Status

PROTOCOL_VERSION = 8  # bumped when a request, reply, record layout or enum changes meaning

MAGIC = 0x0CCADD02
HEADER_LEN = 16
STATUS_LEN = 48
TRACE_IDX = 16  # input / action indices kept per trace record


class MachineState(IntEnum):
    IDLE = 0  # no mission loaded: the Hold task holds the arm
    READY = 1  # a verified mission is loaded, not running
    RUNNING = 2
    HOLDING = 3  # the mission is suspended; the Hold task holds the arm


class MissionResult(IntEnum):
    NONE = 0
    SUCCESS = 1
    SAFE = 2  # the safe procedure ran to its end
    FAILED = 3  # a type 3 exception inside the safe procedure
    ABORTED = 4  # the operator aborted
    STOPPED = 5  # shut down (SIGTERM) while running


class OperatorAction(IntEnum):
    """Operator actions, as recorded in the trace (the `code` of a COMMAND record)."""

    LOAD = 1
    START = 2
    STOP = 3
    ABORT = 4
    HOLD = 5
    RESUME = 6
    RESET = 7
    TUNE = 8
    SEND = 9
    INJECT = 10
    SHUTDOWN = 11
    CELL = 12  # a peer's signal or its loss (`cell_input`, from the command daemon's cell link)


class Trace(IntEnum):
    """What a trace record is."""

    INSTANT = 0  # an automaton reaction: inputs -> actions
    EVENT = 1  # a task event the automaton does not see (T1, the Hold task's events)
    COMMAND = 2  # an operator action (start, stop, abort, hold, resume, reset, tune)
    FAULT = 3  # the arm safe-stopped: `code` numbers its cause (`describe`'s "faults")


def tune_words(tune: Mapping[str, Any]) -> str:
    """A decoded tune record in words: `Reach.ct.kp[2]: 500 → 600 (tick 48213)`; a vector the
    record had to cut says how long it was."""

    def num(x: float) -> str:  # short, and exact: `orccadctl replay` applies it as logged
        short = f"{x:g}"
        return short if float(short) == x else repr(x)

    def values(v: list[float]) -> str:
        return num(v[0]) if len(v) == 1 else "[" + ", ".join(num(x) for x in v) + "]"

    cut = f" (first {len(tune['new'])} of {tune['n']})" if tune["n"] > len(tune["new"]) else ""
    return f"{tune['path']}: {values(tune['old'])} → {values(tune['new'])}{cut} (tick {tune['tick']})"


def exception_of(event: Mapping[str, Any]) -> int:
    """A decoded trace record's exception class, from the kinds it carries (never its names):
    3 for a type 3 exception or a safe stop's cause, 2 for a type 2, 0 for anything else."""
    if event.get("kind") == "fault":
        return 3
    kinds = event.get("input_kinds") or [event.get("event_kind")]
    return 3 if "t3" in kinds else 2 if "t2" in kinds else 0


class H(IntEnum):
    """Header slots."""

    MAGIC = 0
    DOF = 1
    TICK_LEN = 2
    TICK_WIDTH = 3
    TICK_HEAD = 4
    TRACE_LEN = 5
    TRACE_WIDTH = 6
    TRACE_HEAD = 7
    PID = 8
    HEARTBEAT_NS = 9
    PERIOD_S = 10
    TICKS = 11  # written by the control thread every tick
    OVERRUNS = 12
    CONSECUTIVE_OVERRUNS = 13
    SWITCHES = 14


class S(IntEnum):
    """Status slots (under the sequence lock in slot 0)."""

    SEQ = 0
    MACHINE = 1  # MachineState
    AUTOMATON_STATE = 2
    MISSION_GEN = 3  # changes each time a mission is loaded (names may change)
    INSTANTS = 4
    RESULT = 5  # MissionResult of the last run
    FAULTED = 6  # 0, or the safe stop's number (counts from 1): `reset` is needed before motion
    HELPER_PID = 7  # a process the resource runs (the simulated plant), 0 if none


class T(IntEnum):
    """Scalar fields of a tick record, in order; `TICK_VECTORS` follow, one value per joint."""

    SEQ = 0
    T_S = 1  # release time of the tick (s, the loop's clock)
    WAKE_US = 2  # wake-up latency
    COMPUTE_US = 3
    TASK = 4  # telemetry task id: the Hold tasks (one per resource), then the mission's (`describe`'s tasks)
    PHASE = 5  # Phase
    WROTE = 6  # 1 if a command was sent
    STATUS = 7  # Status flags of the resource
    MODE = 8  # CommandMode of the command sent (the `cmd` vector: what went to the device)


TICK_FIELDS = tuple(f.name.lower() for f in T)
TICK_VECTORS = ("q", "dq", "tau", "cmd")


class R(IntEnum):
    """Fields of a trace record, in order; then `TRACE_IDX` input and `TRACE_IDX` action indices."""

    SEQ = 0
    KIND = 1  # Trace
    T_S = 2
    WALL_S = 3
    STATE_FROM = 4
    STATE_TO = 5
    CODE = 6  # event id (EVENT) or OperatorAction (COMMAND)
    N_IN = 7
    N_ACT = 8
    MISSION_GEN = 9  # the mission loaded when it was written (S.MISSION_GEN): names its indices


TRACE_WIDTH = len(R) + 2 * TRACE_IDX


@dataclass(frozen=True)
class TuneRecord:
    """A tune as its trace record (a COMMAND, code TUNE) carries it: in the input slots the task's
    telemetry id, the parameter's index in that task's `tunables`, the element (-1: the whole
    parameter), the tick that applied it and how many values; in the action slots the values
    before, then after (at most `TRACE_IDX // 2` of each: a longer vector is cut, `n` says so)."""

    task: int
    param: int
    element: int
    tick: int
    old: list[float]
    new: list[float]
    n: int = 0  # how many values the parameter took (0: len(new))

    def encode(self) -> tuple[list[float], list[float]]:
        k = min(len(self.new), TRACE_IDX // 2)
        head = [self.task, self.param, self.element, self.tick, self.n or len(self.new)]
        return [float(x) for x in head], [*self.old[:k], *self.new[:k]]

    @staticmethod
    def decode(head: list[float], values: list[float]) -> TuneRecord:
        task, param, element, tick, n = (int(x) for x in head[:5])
        k = len(values) // 2
        return TuneRecord(task, param, element, tick, values[:k], values[k:], n)


def tick_width(dof: int, extra: int = 0) -> int:
    """The scalar fields, then q, dq, tau and the command sent, one value per joint each, then
    `extra` values: the resource's own signals (`TickLayout.signals`)."""
    return len(T) + len(TICK_VECTORS) * dof + extra


class TickLayout:
    """Where each joint vector of a tick record lies, for `dof` joints, and after them the
    resource's own signals (`signals`: name and size, in its description's order: a UR's wrench,
    a camera's features): the only place that computes an offset into the record (slices of a
    record, or of an array of records on its last axis: `recs[..., layout.cmd]`)."""

    __slots__ = ("cmd", "dof", "dq", "q", "signals", "tau", "width")

    def __init__(self, dof: int, signals: Sequence[tuple[str, int]] = ()) -> None:
        self.dof = dof
        self.signals: dict[str, slice] = {}
        self.q, self.dq, self.tau, self.cmd = (self.vector(name) for name in TICK_VECTORS)
        start = tick_width(dof)
        for name, size in signals:
            if name in TICK_FIELDS or name in TICK_VECTORS or name in self.signals:
                raise ValueError(f"a resource's signal {name!r} takes the name of a tick field")
            self.signals[name] = slice(start, start + size)
            start += size
        self.width = start

    def vector(self, name: str) -> slice:
        """`q`, `dq`, `tau`, `cmd` or one of `signals` (ValueError for another name)."""
        if name in TICK_VECTORS:
            start = len(T) + TICK_VECTORS.index(name) * self.dof
            return slice(start, start + self.dof)
        sl = self.signals.get(name)
        if sl is None:
            raise ValueError(f"{name!r} is not in the tick record")
        return sl

    def column(self, name: str, joint: int) -> int:
        """The column of one joint's value of vector `name`."""
        if not 0 <= joint < self.dof:
            raise IndexError(f"joint {joint} of {self.dof}")
        return int(self.vector(name).start) + joint


@dataclass(frozen=True)
class Layout:
    """Sizes of one telemetry block (`extra`: the values of the resource's signals per tick)."""

    dof: int
    tick_len: int
    trace_len: int
    extra: int = 0

    @property
    def tick_width(self) -> int:
        return tick_width(self.dof, self.extra)

    @property
    def size_bytes(self) -> int:
        n = HEADER_LEN + STATUS_LEN + self.tick_len * self.tick_width + self.trace_len * TRACE_WIDTH
        return 8 * n


def status_names(flags: int) -> list[str]:
    """The `Status` flags set in `flags`, lower case (`["stopped", "torque_off"]`)."""
    return [f.name.lower() for f in Status if f and int(flags) & f and f.name]


__all__ = [
    "HEADER_LEN",
    "MAGIC",
    "PROTOCOL_VERSION",
    "STATUS_LEN",
    "TICK_FIELDS",
    "TICK_VECTORS",
    "TRACE_IDX",
    "TRACE_WIDTH",
    "CommandMode",
    "H",
    "Layout",
    "MachineState",
    "MissionResult",
    "OperatorAction",
    "Phase",
    "R",
    "S",
    "Status",
    "T",
    "TickLayout",
    "Trace",
    "status_names",
    "tick_width",
]
