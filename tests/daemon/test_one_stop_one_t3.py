"""One stop, one type 3: a resource fault that safe-stopped the arm during a mission's task is not
raised again by the Hold task that holds the resource afterwards (it still reports the fault), until
a reset cleared the stop; a fault after the reset is a new type 3."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import pytest

from orccadd.daemon.machine import Machine
from orccadd.daemon.replies import Pending
from orccadd.task.events import EventKind
from orccadd.types import Status
from tests.daemon.test_inline import load_and_start, run


def t3_events(machine: Machine) -> list[str]:
    """The name of every type 3 event pushed so far (the queue's ring has not wrapped)."""
    queue, registry = machine.default.loop.queue, machine.registry
    assert queue.pushed <= 1024
    infos = [registry.info(queue.event_at(i)) for i in range(queue.pushed)]
    return [e.name for e in infos if e.kind is EventKind.T3]


def run_until(machine: Machine, what: str, done: Callable[[], bool], timeout_s: float = 30.0) -> None:
    """Tick (simulated time) until `done`, the threads the machine waits for (a device's reset)
    running between ticks; bounded in wall time."""
    end = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < end, f"not within {timeout_s:g} s: {what}"
        run(machine, 1, busy=False)
        time.sleep(0.001)


@pytest.mark.parametrize("busy", [False, True], ids=["switch-in-the-tick", "switch-a-tick-later"])
def test_a_device_fault_mid_mission_is_one_type_3_until_reset(
    machine: Machine, tmp_path: Path, busy: bool
) -> None:
    res = machine.default.resource
    load_and_start(machine, tmp_path)
    run(machine, 300, busy=False)
    assert machine.default.loop.active is not machine.default.loop.hold  # a mission's task runs
    res.inject_fault("device", "test fault")
    run(machine, 5, busy=busy)  # the type 3, the safe procedure, Hold takes the resource
    run_until(machine, "the arm stopped", lambda: bool(res.state.status & Status.STOPPED))
    run(machine, 200, busy=False)  # Hold ticks on a resource that still reports the fault
    assert machine.default.loop.active is machine.default.loop.hold
    assert res.state.status & Status.FAULT
    names = t3_events(machine)
    assert len(names) == 1 and names[0].endswith(".T3.ResourceFault"), names
    assert not names[0].startswith("Hold."), names

    with machine.reactor.held():
        machine.command("send", {"input": "Stop"})  # the safe procedure's acknowledgement
    run(machine, 5, busy=False)
    with machine.reactor.held():
        reply = machine.command("reset", {})
    if isinstance(reply, Pending):
        run_until(machine, "the reset answered", lambda: reply.poll() is not None)
    assert not machine.default.supervisor.fault and not res.stopping_or_stopped
    run(machine, 50, busy=False)
    assert t3_events(machine) == names  # still one

    res.inject_fault("device", "a second fault, after the reset")
    run(machine, 5, busy=False)
    assert t3_events(machine) == [*names, "Hold.T3.ResourceFault"]  # a new stop, a new type 3
