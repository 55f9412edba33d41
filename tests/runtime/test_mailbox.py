"""The single-producer/single-consumer mailbox: order, exactly once, acknowledgements, across threads."""

from __future__ import annotations

import random
import threading
import time

import pytest

from orccadd.runtime.mailbox import Mailbox, MailboxFullError


def test_items_are_applied_in_order_once_and_acknowledged_with_the_tick() -> None:
    box: Mailbox[int] = Mailbox(4)
    got: list[int] = []
    s1, s2 = box.post(10), box.post(11)
    assert (s1, s2) == (1, 2)
    assert box.acked(s1) is None
    box.drain(got.append, tick=7)
    box.drain(got.append, tick=8)  # nothing new: nothing applied twice
    assert got == [10, 11]
    assert box.acked(s1) == box.acked(s2) == 7


def test_a_full_mailbox_refuses_and_loses_nothing() -> None:
    box: Mailbox[int] = Mailbox(2)
    box.post(1)
    box.post(2)
    with pytest.raises(MailboxFullError):
        box.post(3)
    got: list[int] = []
    box.drain(got.append, tick=1)
    assert got == [1, 2]
    box.post(3)
    box.drain(got.append, tick=2)
    assert got == [1, 2, 3]


def test_a_producer_and_a_consumer_thread_lose_nothing() -> None:
    """The daemon's use: the command thread posts while the control thread drains every tick."""
    box: Mailbox[int] = Mailbox(8)
    n = 20_000
    got: list[int] = []
    stop = threading.Event()

    def consumer() -> None:
        tick = 0
        while not stop.is_set() or box.waiting:
            tick += 1
            box.drain(got.append, tick)
            if random.random() < 0.01:
                time.sleep(0)

    t = threading.Thread(target=consumer)
    t.start()
    sent = 0
    seqs = []
    while sent < n:
        try:
            seqs.append(box.post(sent))
            sent += 1
        except MailboxFullError:
            time.sleep(0)
    stop.set()
    t.join(timeout=30)
    assert got == list(range(n))
    assert box.acked(seqs[-1]) is not None
