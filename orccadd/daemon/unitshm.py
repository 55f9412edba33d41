"""What a resource's unit process and the automaton process share (issue 44, item 2: a process
per clock domain; work in progress on this branch, not wired into the daemon yet).

One shared-memory block per unit, laid out as float64 words (`UnitChannel`), with one writer per
field and counters published last (x86 keeps stores in order, and CPython runs a thread's
stores in program order):

- the switch mailbox: the automaton writes (task index, fresh) then bumps `request`; the unit's
  control thread applies it at its next tick and copies `request` into `applied`;
- the event ring: the control thread writes (t_s, event id) then bumps `pushed`; the automaton
  reads from its own `tail` (a reader that fell a ring behind counts what it lost);
- `TryLock`: the process-shared try-lock of the in-tick reaction, on `flock` (one system call a
  try; a process that dies holding it releases it).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from multiprocessing import shared_memory

import numpy as np
import numpy.typing as npt

from orccadd.task.events import EventQueue
from orccadd.wire.telemetry import attach_shared

MAGIC = 0x0E44_0001


class W(IntEnum):
    """The block's header words."""

    MAGIC = 0
    RING_LEN = 1
    REQUEST = 2  # switch requests made (the automaton's)
    TASK = 3  # the last request's task index (-1: the unit's Hold task)
    FRESH = 4  # the last request starts from the measured state (1) or continues the command (0)
    APPLIED = 5  # switch requests applied (the control thread's)
    PUSHED = 6  # events ever pushed (the control thread's)
    TAIL = 7  # events consumed (the automaton's, as it drains)
    STOP = 8  # safe stops requested (the automaton's)
    STOPS_TAKEN = 9  # safe stops taken (the control thread's)
    # the reactions the unit may take in the tick of its event (`daemon.reactions`): written
    # under the station's try-lock, by the automaton (the table) or a unit (what it took)
    TABLE_CAP = 10  # rows the table holds
    TABLE_WIDTH = 11  # words a row: the event id, then per unit the task it switches to
    TABLE_ROWS = 12  # rows valid now (0: none, react in the automaton's thread)
    TAKEN = 13  # reactions taken in a tick (the unit's)
    BOOKED = 14  # of those, booked by the automaton
    TAKEN_EVENT = 15  # the last one's: its event id, time, and queue indices [first, end)
    TAKEN_T_S = 16
    TAKEN_FIRST = 17
    TAKEN_END = 18


HEADER = len(W)
TABLE_ROWS_MAX = 64  # events of one resource a mission reacts to in their tick, at most
NO_TASK = -2.0  # a table row's task for a unit whose task does not change


@dataclass
class Event:
    t_s: float
    event_id: int


class UnitChannel:
    """The shared block of one unit. `create` in the automaton process, `attach` in the unit's."""

    def __init__(self, shm: shared_memory.SharedMemory, owner: bool) -> None:
        self.shm = shm
        self.owner = owner
        words: npt.NDArray[np.float64] = np.ndarray((shm.size // 8,), dtype=np.float64, buffer=shm.buf)
        if int(words[W.MAGIC]) != MAGIC:
            raise ValueError(f"shared memory {shm.name!r} is not a unit's channel")
        self.words = words
        n = int(words[W.RING_LEN])
        self.ring_len = n
        self.ring = words[HEADER : HEADER + 2 * n].reshape(n, 2)  # (t_s, event id)
        rows, width = int(words[W.TABLE_CAP]), int(words[W.TABLE_WIDTH])
        at = HEADER + 2 * n
        self.table = words[at : at + rows * width].reshape(rows, width)
        self.tail = 0  # the consumer's: the next event to read (not shared)
        self.lost = 0  # events the consumer came too late for

    @staticmethod
    def create(
        ring_len: int = 4096, units: int = 1, index: int = 0, table_rows: int = TABLE_ROWS_MAX
    ) -> UnitChannel:
        """A new channel for unit `index` of a station of `units` resources (its Hold task's
        index is `index`: the automaton numbers the Hold tasks first)."""
        width = 1 + units
        size = HEADER + 2 * ring_len + table_rows * width
        shm = shared_memory.SharedMemory(create=True, size=8 * size)
        words = np.ndarray((size,), dtype=np.float64, buffer=shm.buf)
        words[:] = 0.0
        words[W.RING_LEN] = ring_len
        words[W.TASK] = index
        words[W.TABLE_CAP] = table_rows
        words[W.TABLE_WIDTH] = width
        words[W.MAGIC] = MAGIC
        return UnitChannel(shm, owner=True)

    @staticmethod
    def attach(name: str) -> UnitChannel:
        return UnitChannel(attach_shared(name), owner=False)

    @property
    def name(self) -> str:
        return self.shm.name

    def close(self) -> None:
        del self.words, self.ring, self.table
        self.shm.close()
        if self.owner:
            with contextlib.suppress(FileNotFoundError):
                self.shm.unlink()

    # ---- the switch mailbox ---------------------------------------------------------------
    def request_switch(self, task: int, fresh: bool) -> int:
        """The automaton's: make task `task` (-1: Hold) active at the unit's next tick."""
        w = self.words
        w[W.TASK] = task
        w[W.FRESH] = 1.0 if fresh else 0.0
        request = int(w[W.REQUEST]) + 1
        w[W.REQUEST] = request  # published last
        return request

    def switched(self, request: int) -> bool:
        return int(self.words[W.APPLIED]) >= request

    def requests_applied(self) -> bool:
        return int(self.words[W.APPLIED]) == int(self.words[W.REQUEST])

    # ---- the safe stop ----------------------------------------------------------------------
    def request_stop(self) -> None:
        """The automaton's: safe-stop the resource at the unit's next tick."""
        self.words[W.STOP] = int(self.words[W.STOP]) + 1

    def take_stop(self) -> bool:
        """The control thread's, at a tick's start: a safe stop was requested since the last."""
        w = self.words
        wanted = w[W.STOP]
        if wanted == w[W.STOPS_TAKEN]:
            return False
        w[W.STOPS_TAKEN] = wanted
        return True

    def take_switch(self) -> tuple[int, bool] | None:
        """The control thread's, at the start of a tick: the request not applied yet, if any
        (task index, fresh), marked applied."""
        w = self.words
        request = int(w[W.REQUEST])
        if request == int(w[W.APPLIED]):
            return None
        task, fresh = int(w[W.TASK]), bool(w[W.FRESH])
        if int(w[W.REQUEST]) != request:  # a newer one came meanwhile: take that at the next tick
            return None
        w[W.APPLIED] = request
        return task, fresh

    # ---- the event ring -------------------------------------------------------------------
    def push(self, t_s: float, event_id: int) -> None:
        """The control thread's (tick-safe): one event, published by `pushed`."""
        w = self.words
        pushed = int(w[W.PUSHED])
        slot = self.ring[pushed % self.ring_len]
        slot[0] = t_s
        slot[1] = event_id
        w[W.PUSHED] = pushed + 1

    @property
    def pushed(self) -> int:
        return int(self.words[W.PUSHED])

    # ---- the reactions taken in the tick of their event (`daemon.reactions`) --------------
    # all under the station's try-lock: the automaton's work holds it, a tick only tries it
    @property
    def wanted_task(self) -> int:
        """The task the automaton wants on this unit: the last request's, or the last switch a
        unit took in its tick (-1: the Hold task)."""
        return int(self.words[W.TASK])

    @property
    def consumed(self) -> int:
        """The events the automaton has consumed (as `tail`, read by any process)."""
        return int(self.words[W.TAIL])

    def has_table(self) -> bool:
        """Reactions to take in a tick are published (tick-safe)."""
        return bool(self.words[W.TABLE_ROWS])

    def drained(self) -> bool:
        """Every event pushed has been consumed by the automaton."""
        return int(self.words[W.PUSHED]) == int(self.words[W.TAIL])

    def publish(self, rows: list[tuple[int, list[float]]]) -> None:
        """The automaton's: the reactions this unit may take now, per event id the task of each
        unit of the station (`NO_TASK`: unchanged). Those past the table's size are left to the
        automaton's thread."""
        t = self.table
        n = min(len(rows), len(t))
        for i, (event_id, tasks) in enumerate(rows[:n]):
            t[i, 0] = event_id
            t[i, 1 : 1 + len(tasks)] = tasks
        self.words[W.TABLE_ROWS] = n

    def invalidate(self) -> None:
        """No reaction to take in a tick until the automaton publishes again."""
        self.words[W.TABLE_ROWS] = 0

    def row_of(self, event_id: int) -> npt.NDArray[np.float64] | None:
        """The unit's (tick-safe): the table's row for `event_id`, None if it has none."""
        t = self.table
        for i in range(int(self.words[W.TABLE_ROWS])):
            if t[i, 0] == event_id:
                return t[i]  # type: ignore[no-any-return]
        return None

    def take(self, event_id: int, t_s: float, first: int, end: int, own_task: float) -> None:
        """The unit's: it took the reaction to `event_id` (queue indices [first, end)) in its
        tick, switching itself to `own_task` (`NO_TASK`: no switch)."""
        w = self.words
        w[W.TAKEN_EVENT] = event_id
        w[W.TAKEN_T_S] = t_s
        w[W.TAKEN_FIRST] = first
        w[W.TAKEN_END] = end
        if own_task != NO_TASK:
            w[W.TASK] = own_task  # what the automaton wants on it now (no request to apply)
        w[W.TAKEN] = int(w[W.TAKEN]) + 1

    def taken(self) -> tuple[int, float, int, int] | None:
        """The automaton's: a reaction taken in a tick and not booked yet (event id, time, queue
        indices [first, end)), marked booked; None if none."""
        w = self.words
        if int(w[W.TAKEN]) == int(w[W.BOOKED]):
            return None
        w[W.BOOKED] = w[W.TAKEN]
        return int(w[W.TAKEN_EVENT]), float(w[W.TAKEN_T_S]), int(w[W.TAKEN_FIRST]), int(w[W.TAKEN_END])

    def drain(self) -> list[Event]:
        """The automaton's: the events pushed since the last drain, in order; those overwritten
        before it came are counted in `lost`."""
        pushed = int(self.words[W.PUSHED])
        if pushed - self.tail > self.ring_len:
            self.lost += pushed - self.ring_len - self.tail
            self.tail = pushed - self.ring_len
        out = []
        for i in range(self.tail, pushed):
            t_s, eid = self.ring[i % self.ring_len]
            out.append(Event(float(t_s), int(eid)))
        if int(self.words[W.PUSHED]) - self.tail > self.ring_len:  # overwritten while read
            lapped = int(self.words[W.PUSHED]) - self.ring_len - self.tail
            self.lost += lapped
            out = out[lapped:]
        self.tail = pushed
        self.words[W.TAIL] = pushed
        return out


class TryLock:
    """A lock shared by processes, never waited for: `try_acquire` takes it or returns False at
    once. On `flock` of the file `path` (each process opens it itself); the kernel releases it
    when its holder's descriptor closes, its process dying included."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)

    def try_acquire(self) -> bool:
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        return True

    def acquire(self) -> None:
        """Wait for it (the automaton thread's, never a tick's)."""
        fcntl.flock(self.fd, fcntl.LOCK_EX)

    def release(self) -> None:
        fcntl.flock(self.fd, fcntl.LOCK_UN)

    def close(self) -> None:
        os.close(self.fd)


class ChannelQueue(EventQueue):
    """The unit process's event queue: what its tasks and loop push goes into the channel's ring,
    for the automaton's process to drain (`UnitChannel.drain`). The counter goes on from the
    channel's (a unit started again continues the ring)."""

    def __init__(self, channel: UnitChannel) -> None:
        super().__init__(1)
        self.channel = channel
        self.pushed = channel.pushed
        # told each event before it is pushed (the unit sends a type 3's fault first)
        self.before_push: Callable[[int], None] | None = None

    def push(self, t_s: float, event_id: int) -> None:
        if self.before_push is not None:
            self.before_push(event_id)
        self.channel.push(t_s, event_id)
        self.pushed += 1

    @property
    def tail(self) -> int:
        """The events the automaton's process has consumed."""
        return int(self.channel.words[W.TAIL])

    def event_at(self, index: int) -> int:
        return int(self.channel.ring[index % self.channel.ring_len][1])

    def __len__(self) -> int:
        return self.pushed - self.tail

    def drain(self) -> list[tuple[float, int]]:
        raise TypeError("a unit's events are drained by the automaton's process (UnitChannel.drain)")
