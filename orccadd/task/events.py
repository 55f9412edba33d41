"""Typed, named events of Robot-Tasks, and the queue they travel in from the control thread.

Names are what the procedure language refers to: `MoveHome.done`, `MoveHome.T2.TrackingLost`,
`MoveHome.T3.LimitViolation`, `MoveHome.sync.HalfWay`, `MoveHome.T1.SlowDown`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class EventKind(IntEnum):
    """ORCCAD's event classes (seed 000 §2.2)."""

    POST = 0  # postcondition: the task ended successfully
    T1 = 1  # type 1 exception: handled inside the task (e.g. lower a speed parameter)
    T2 = 2  # type 2 exception: the task cannot complete, the procedure chooses what next
    T3 = 3  # type 3 exception: fatal, safe stop at once, then the safe procedure
    SYNC = 4  # synchronisation signal
    PRE = 5  # the preconditions held: the law started (only for tasks with preconditions)
    INPUT = 6  # a resource's named digital input rose (`R.X`: "task" is the resource)


KIND_PREFIX = {
    EventKind.POST: "",
    EventKind.T1: "T1.",
    EventKind.T2: "T2.",
    EventKind.T3: "T3.",
    EventKind.SYNC: "sync.",
    EventKind.PRE: "",
    EventKind.INPUT: "",
}

PRECONDITION_TIMEOUT = "PreconditionTimeout"


def event_name(task: str, kind: EventKind, name: str) -> str:
    if kind is EventKind.POST:
        return f"{task}.done"
    if kind is EventKind.PRE:
        return f"{task}.pre"
    return f"{task}.{KIND_PREFIX[kind]}{name}"


@dataclass(frozen=True)
class EventInfo:
    id: int
    name: str
    task: str
    kind: EventKind


class EventRegistry:
    """Event names ↔ small integers (bit positions for the automaton's bitmasks)."""

    def __init__(self) -> None:
        self._by_name: dict[str, EventInfo] = {}
        self._by_id: list[EventInfo] = []

    def register(self, task: str, kind: EventKind, name: str) -> int:
        full = event_name(task, kind, name)
        info = self._by_name.get(full)
        if info is None:
            info = EventInfo(len(self._by_id), full, task, kind)
            self._by_name[full] = info
            self._by_id.append(info)
        return info.id

    def id(self, name: str) -> int:
        return self._by_name[name].id

    def seed(self, infos: list[EventInfo]) -> None:
        """Register `infos` (another registry's, in id order) first: the tasks built after get
        that registry's ids (a unit process's, from the automaton's). `ValueError` if this
        registry already gave one of those ids to another event."""
        for info in infos:
            have = self._by_name.get(info.name)
            if have is None and info.id == len(self._by_id):
                self._by_name[info.name] = info
                self._by_id.append(info)
            elif have is None or have.id != info.id:
                raise ValueError(f"event {info.name!r}: id {info.id} here is another event's")

    def infos(self) -> list[EventInfo]:
        """Every event, in id order (what `seed` takes)."""
        return list(self._by_id)

    def info(self, event_id: int) -> EventInfo:
        return self._by_id[event_id]

    def names(self) -> list[str]:
        return [e.name for e in self._by_id]

    def kinds(self) -> list[EventKind]:
        """The kind of each event, by id."""
        return [e.kind for e in self._by_id]

    def __len__(self) -> int:
        return len(self._by_id)


class EventQueue:
    """Fixed-capacity ring of (time, event id), written by the control thread in a tick.

    `push` never allocates; when full, the oldest entries are overwritten and counted in
    `dropped` (the consumer is too slow). `drain` is for the consumer, not for a tick.
    """

    def __init__(self, capacity: int = 1024) -> None:
        self._t = np.zeros(capacity)
        self._id = np.zeros(capacity, dtype=np.int64)
        self._cap = capacity
        # how many events were ever pushed (the producer's counter, the next write's index): an
        # attribute, not a property, read three times a tick by the control loop
        self.pushed = 0
        self._tail = 0  # next read
        self.dropped = 0

    def push(self, t_s: float, event_id: int) -> None:
        i = self.pushed % self._cap
        self._t[i] = t_s
        self._id[i] = event_id
        self.pushed += 1
        if self.pushed - self._tail > self._cap:
            self._tail += 1
            self.dropped += 1

    @property
    def tail(self) -> int:
        """The index of the next event `drain` returns (the events before it are consumed)."""
        return self._tail

    def event_at(self, index: int) -> int:
        """The id of event `index` (`tail` ≤ index < `pushed`), left in the queue."""
        return int(self._id[index % self._cap])

    def drain(self) -> list[tuple[float, int]]:
        out = []
        while self._tail < self.pushed:
            i = self._tail % self._cap
            out.append((float(self._t[i]), int(self._id[i])))
            self._tail += 1
        return out

    def __len__(self) -> int:
        return self.pushed - self._tail
