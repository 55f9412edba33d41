"""A unit's shared channel across two real processes: switch requests applied once and in order,
events in order with none invented, a slow reader told what it lost; the process-shared
try-lock excludes another process and is released when its holder dies."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.daemon.unitshm import TryLock, UnitChannel

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def channel() -> Iterator[UnitChannel]:
    ch = UnitChannel.create(ring_len=64)
    try:
        yield ch
    finally:
        ch.close()


def child(code: str, *args: str) -> subprocess.Popen[str]:
    """A second Python process running `code` (its argv after it: `args`)."""
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(code), *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_switch_requests_are_taken_once_and_the_last_one_wins(channel: UnitChannel) -> None:
    unit = UnitChannel.attach(channel.name)
    try:
        assert unit.take_switch() is None
        first = channel.request_switch(3, fresh=False)
        assert not channel.switched(first)
        assert unit.take_switch() == (3, False) and channel.switched(first)
        assert unit.take_switch() is None  # once
        channel.request_switch(4, fresh=False)
        last = channel.request_switch(-1, fresh=True)  # two before a tick: the last one counts
        assert unit.take_switch() == (-1, True) and channel.switched(last)
    finally:
        unit.close()


def test_events_cross_processes_in_order_and_a_late_reader_counts_what_it_lost(
    channel: UnitChannel,
) -> None:
    producer = """
        import sys
        from orccadd.daemon.unitshm import UnitChannel
        ch = UnitChannel.attach(sys.argv[1])
        for k in range(int(sys.argv[2])):
            ch.push(k * 0.001, k)
        ch.close()
    """
    p = child(producer, channel.name, "40")
    assert p.wait(timeout=60) == 0, p.stderr.read() if p.stderr else ""
    got = channel.drain()
    assert [e.event_id for e in got] == list(range(40)) and got[1].t_s == pytest.approx(0.001)
    assert channel.lost == 0 and channel.drain() == []
    p = child(producer, channel.name, "200")  # more than the ring holds before the next drain
    assert p.wait(timeout=60) == 0, p.stderr.read() if p.stderr else ""
    got = channel.drain()
    assert len(got) == 64 and channel.lost == 200 - 64
    assert [e.event_id for e in got] == list(range(136, 200))  # the newest, in order


def test_the_try_lock_excludes_another_process_and_is_freed_when_its_holder_dies(tmp_path: Path) -> None:
    path = str(tmp_path / "reaction.lock")
    holder = child(
        """
        import sys, time
        from orccadd.daemon.unitshm import TryLock
        lock = TryLock(sys.argv[1])
        assert lock.try_acquire()
        print("held", flush=True)
        time.sleep(60)
        """,
        path,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        lock = TryLock(path)
        try:
            t0 = time.monotonic()
            assert not lock.try_acquire()  # never waits
            assert time.monotonic() - t0 < 1.0
            os.kill(holder.pid, signal.SIGKILL)
            holder.wait(timeout=10)
            assert lock.try_acquire()  # the kernel released the dead holder's lock
            lock.release()
        finally:
            lock.close()
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait()
