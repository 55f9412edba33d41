"""A bounded single-producer / single-consumer mailbox with sequence numbers and acknowledgements.

The producer (the automaton thread, handling a command) posts an item and gets its sequence
number; the consumer (the control thread, at a tick boundary) applies every item posted so far
and records the tick it applied them in; the producer then reads that tick back by sequence
number. Each index is written by one thread only and published by one attribute store, which
the interpreter makes atomic: nothing is lost, nothing is applied twice, no lock is taken.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class MailboxFullError(Exception):
    """More items are waiting than the mailbox holds (the consumer is not running)."""


class Mailbox(Generic[T]):
    def __init__(self, capacity: int = 64) -> None:
        self.capacity = capacity
        self._items: list[T | None] = [None] * capacity
        self._ack_tick: list[int] = [0] * capacity
        self._head = 0  # items posted (producer only)
        self._tail = 0  # items applied (consumer only)

    # ---- producer ---------------------------------------------------------------------------
    def post(self, item: T) -> int:
        """Queue `item`; its sequence number (1, 2, ...). `MailboxFullError` if the consumer lags."""
        head = self._head
        if head - self._tail >= self.capacity:
            raise MailboxFullError(f"{self.capacity} items are waiting: the consumer is not running")
        self._items[head % self.capacity] = item
        self._head = head + 1  # publishes the item
        return head + 1

    def acked(self, seq: int) -> int | None:
        """The tick number item `seq` was applied in, or None while it waits."""
        if seq > self._tail:
            return None
        if seq <= self._tail - self.capacity:
            raise KeyError(f"item {seq} was acknowledged too long ago")
        return self._ack_tick[(seq - 1) % self.capacity]

    @property
    def waiting(self) -> int:
        return self._head - self._tail

    # ---- consumer (tick-safe: no allocation) ---------------------------------------------------
    def drain(self, apply: Callable[[T], None], tick: int) -> None:
        """Apply every item posted so far, in order, and acknowledge each with `tick`."""
        head, tail, cap = self._head, self._tail, self.capacity
        items, acks = self._items, self._ack_tick
        while tail < head:
            i = tail % cap
            item = items[i]
            items[i] = None
            acks[i] = tick
            apply(item)  # type: ignore[arg-type]
            tail += 1
            self._tail = tail
