"""Telemetry from the real-time process to the command daemon: one shared-memory block.

The real-time process writes, never waits and never learns whether anyone reads. The layout and
every index are in `orccadd.wire.schema`.

Ring protocol: the writer marks a slot invalid (`seq = -1`), fills it, then stores its sequence
number and advances the head. A reader copies a slot and keeps it only if its sequence number is
the one expected both before and after the copy, so it never keeps a torn record; records that
were overwritten before it came are counted as lost.
"""

from __future__ import annotations

import contextlib
import os
import weakref
from multiprocessing import resource_tracker, shared_memory

import numpy as np
import numpy.typing as npt

from orccadd.wire.schema import HEADER_LEN, MAGIC, STATUS_LEN, TRACE_WIDTH, H, Layout, S, tick_width

FloatArray = npt.NDArray[np.float64]

# the header's slots each tick writes, as plain ints: looking an IntEnum member up costs ~0.12 µs
# (as `shm_channel.Ctl`)
_TICK_HEAD = int(H.TICK_HEAD)
_HEARTBEAT_NS = int(H.HEARTBEAT_NS)


def attach_shared(name: str) -> shared_memory.SharedMemory:
    """Another process's shared-memory block `name`, attached (not owned: closing it here does
    not unlink it)."""
    shm = shared_memory.SharedMemory(name=name, create=False)
    # Python < 3.13 registers attached blocks too and would unlink the owner's block at exit
    resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
    return shm


class TelemetryBlock:
    """Views on the block. The real-time process creates it; the command daemon attaches."""

    def __init__(self, shm: shared_memory.SharedMemory, owner: bool) -> None:
        self.shm = shm
        self.owner = owner
        buf = np.ndarray((shm.size // 8,), dtype=np.float64, buffer=shm.buf)
        self.header = buf[:HEADER_LEN]
        if int(self.header[H.MAGIC]) != MAGIC:
            raise ValueError(f"shared memory {shm.name!r} is not an orccadd telemetry block")
        self.dof = int(self.header[H.DOF])
        self.tick_len = int(self.header[H.TICK_LEN])
        self.trace_len = int(self.header[H.TRACE_LEN])
        o = HEADER_LEN
        self.status = buf[o : o + STATUS_LEN]
        o += STATUS_LEN
        tw = int(self.header[H.TICK_WIDTH]) or tick_width(self.dof)
        self.ticks = buf[o : o + self.tick_len * tw].reshape(self.tick_len, tw)
        self.tick_width = tw
        self._ticks_at = o  # the first tick record's first word
        o += self.tick_len * tw
        self.trace = buf[o : o + self.trace_len * TRACE_WIDTH].reshape(self.trace_len, TRACE_WIDTH)
        # the same words for the tick's writer: a memoryview stores a float, or copies a vector
        # from another memoryview, in a third of numpy's time (`begin_tick_at`)
        # (a view of `shm.buf` itself: one of the numpy array measured slower in the daemon,
        # `benchmarks/station.py`, a 1 kHz arm's wake-up p99 ×3 beside a second arm switching
        # laws; released before the interpreter closes the block's mmap at exit, which refuses
        # to close while a view of it is left)
        raw = shm.buf
        assert raw is not None
        self.words: memoryview[float] = raw[: buf.size * 8].cast("d")
        weakref.finalize(self, self.words.release)

    @staticmethod
    def create(layout: Layout, period_s: float, name: str | None = None) -> TelemetryBlock:
        shm = shared_memory.SharedMemory(name=name, create=True, size=layout.size_bytes)
        buf = np.ndarray((shm.size // 8,), dtype=np.float64, buffer=shm.buf)
        buf[:] = 0.0
        hdr = buf[:HEADER_LEN]
        hdr[H.DOF] = layout.dof
        hdr[H.TICK_LEN] = layout.tick_len
        hdr[H.TICK_WIDTH] = layout.tick_width
        hdr[H.TRACE_LEN] = layout.trace_len
        hdr[H.TRACE_WIDTH] = TRACE_WIDTH
        hdr[H.PID] = os.getpid()
        hdr[H.PERIOD_S] = period_s
        hdr[H.MAGIC] = MAGIC
        return TelemetryBlock(shm, owner=True)

    @staticmethod
    def attach(name: str) -> TelemetryBlock:
        return TelemetryBlock(attach_shared(name), owner=False)

    @property
    def name(self) -> str:
        return self.shm.name

    @property
    def period_s(self) -> float:
        return float(self.header[H.PERIOD_S])

    def close(self) -> None:
        self.words.release()
        for attr in ("header", "status", "ticks", "trace"):
            setattr(self, attr, None)
        self.shm.close()
        if self.owner:
            with contextlib.suppress(FileNotFoundError):
                self.shm.unlink()

    # ---- writer side (the real-time process; tick-safe, allocation-free) ------------------
    def begin_tick(self) -> FloatArray:
        """The slot for the next tick record (marked invalid); fill it, then `commit_tick`."""
        head = int(self.header[_TICK_HEAD])
        rec = self.ticks[head % self.tick_len]
        rec[0] = -1.0
        return rec  # type: ignore[no-any-return]

    def commit_tick(self, rec: FloatArray, heartbeat_ns: int) -> None:
        hdr = self.header
        head = hdr[_TICK_HEAD] + 1.0
        rec[0] = head
        hdr[_TICK_HEAD] = head
        hdr[_HEARTBEAT_NS] = heartbeat_ns

    def begin_tick_at(self) -> int:
        """`begin_tick` in `words`: the index of the next tick record's first word (its sequence
        number, marked invalid); fill the record's words after it, then `commit_tick_at`."""
        w = self.words
        at = self._ticks_at + int(w[_TICK_HEAD]) % self.tick_len * self.tick_width
        w[at] = -1.0
        return at

    def commit_tick_at(self, at: int, heartbeat_ns: int) -> None:
        """`commit_tick` of the record `begin_tick_at` returned."""
        w = self.words
        head = w[_TICK_HEAD] + 1.0
        w[at] = head
        w[_TICK_HEAD] = head
        w[_HEARTBEAT_NS] = heartbeat_ns

    def begin_trace(self) -> FloatArray:
        head = int(self.header[H.TRACE_HEAD])
        rec = self.trace[head % self.trace_len]
        rec[0] = -1.0
        rec[1:] = 0.0
        return rec  # type: ignore[no-any-return]

    def commit_trace(self, rec: FloatArray) -> None:
        head = self.header[H.TRACE_HEAD] + 1.0
        rec[0] = head
        self.header[H.TRACE_HEAD] = head

    def write_status(self, values: dict[int, float]) -> None:
        st = self.status
        st[S.SEQ] += 1.0  # odd: writing
        for k, v in values.items():
            st[k] = v
        st[S.SEQ] += 1.0


class RingReader:
    """Follows one ring of a block from a chosen start; `poll()` returns the new records."""

    def __init__(self, ring: FloatArray, header: FloatArray, head_slot: int, from_now: bool = True) -> None:
        self.ring = ring
        self.header = header
        self.head_slot = head_slot
        self.next = int(header[head_slot]) if from_now else max(0, int(header[head_slot]) - len(ring))
        self.lost = 0

    def poll(self, max_records: int = 100_000) -> FloatArray:
        head = int(self.header[self.head_slot])
        n = len(self.ring)
        if head - self.next > n:
            self.lost += head - n - self.next
            self.next = head - n
        stop = min(head, self.next + max_records)
        if stop <= self.next:
            return np.empty((0, self.ring.shape[1]))
        idx = np.arange(self.next, stop) % n
        out = self.ring[idx].copy()  # fancy indexing copies
        expect = np.arange(self.next + 1, stop + 1, dtype=np.float64)
        ok = (out[:, 0] == expect) & (self.ring[idx, 0] == expect)
        self.lost += int((~ok).sum())
        self.next = stop
        return out[ok]  # type: ignore[no-any-return]


def read_status(block: TelemetryBlock, tries: int = 100) -> FloatArray:
    """A consistent copy of the status area (retries while the writer is in the middle)."""
    st = block.status
    for _ in range(tries):
        s0 = st[S.SEQ]
        if int(s0) % 2:
            continue
        copy = st.copy()
        if st[S.SEQ] == s0:
            return copy
    return st.copy()
