"""These tests run the control loop in the test's own thread: at real-time priority, as the
daemon runs its loop, so that a busy machine (another process beside `make test`) delays it no
more than it would the daemon's. Below the simulators' (70): they are the hardware."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest

LOOP_PRIORITY = 50


@pytest.fixture(autouse=True)
def loop_at_realtime_priority(request: pytest.FixtureRequest) -> Iterator[None]:
    # no reset-on-fork: the threads the resource starts (a bus's reader, a periodic heartbeat)
    # inherit it, as they would run beside a real-time loop; a simulator the test starts raises
    # its own priority. A module may opt out (`LOOP_AT_REALTIME = False`): the Dynamixel SDK
    # polls its port in a busy loop, which at real-time priority keeps the kernel's tty worker
    # (time-shared) from delivering the answer it waits for.
    if not getattr(request.module, "LOOP_AT_REALTIME", True):
        yield
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(LOOP_PRIORITY))
    except PermissionError:  # not root: the test runs, at normal priority
        yield
        return
    try:
        yield
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
