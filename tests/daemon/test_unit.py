"""A resource's unit starts its control thread and returns once it ticks, hands a failure of that
thread to the automaton thread once, starts it again on request, and joins every thread it owns."""

from __future__ import annotations

import time

from orccadd.daemon.machine import Machine
from orccadd.runtime.rt import RealtimeReport
from orccadd.types import Status
from orccadd.wire.schema import H


def no_realtime(priority: int) -> RealtimeReport:
    return RealtimeReport()  # a test's threads stay time-shared


def wait_for(pred: object, timeout_s: float = 10.0) -> None:
    end = time.monotonic() + timeout_s
    while not pred():  # type: ignore[operator]
        assert time.monotonic() < end, "condition not met"
        time.sleep(0.001)


def test_start_returns_once_held_and_a_failure_is_taken_once_then_a_restart_ticks_again(
    machine: Machine,
) -> None:
    u = machine.default
    assert not u.control_running() and not u.control_ended()  # never started: nothing to restart
    u.start_control(no_realtime, 0)
    try:
        assert int(u.tel.header[H.TICKS]) > 0 and u.loop.active is u.loop.hold  # held
        assert u.control_running() and u.take_failure() == ""
        u.loop.inject_failure()
        wait_for(u.control_ended)
        assert u.resource.stopping_or_stopped  # its dying act: the resource's own safe stop
        assert (
            u.take_failure()
            == "its control thread failed: RuntimeError: injected failure of the control thread"
        )
        assert u.take_failure() == ""  # once
        assert [name for name, _ in u.threads.errors] == []  # the unit's own, not a lost exception
        ticks = int(u.tel.header[H.TICKS])
        u.restart_control()
        assert u.control_running() and int(u.tel.header[H.TICKS]) > ticks
    finally:
        u.stop()
        assert u.join(5.0) == []
    assert not u.control_running() and u.threads.alive() == []


def test_a_failure_becomes_the_active_tasks_type_3_and_the_resources_stop_cause(machine: Machine) -> None:
    u = machine.default
    u.start_control(no_realtime, 0)
    try:
        u.loop.inject_failure()
        wait_for(u.control_ended)
        with machine.reactor.held():
            machine.on_events()
        cause = u.supervisor.fault
        assert cause is not None and cause.event == "Hold.T3.LawError", cause
        assert cause.fault.kind == "internal" and "injected failure" in cause.fault.text
        assert u.resource.state.status & Status.STOPPED or u.resource.stopping_or_stopped
    finally:
        u.stop()
        u.join(5.0)


def test_the_status_and_the_trace_are_the_daemons_own_block_not_a_resources(machine: Machine) -> None:
    u = machine.default
    assert machine.pub.tel is not u.tel  # no resource carries what belongs to every resource
    before = int(machine.pub.tel.header[H.TRACE_HEAD])
    machine.command("abort", {})  # an operator command: a trace record (and a fault)
    assert int(machine.pub.tel.header[H.TRACE_HEAD]) > before
    assert int(u.tel.header[H.TRACE_HEAD]) == 0  # the resource's block: its ticks only
    assert machine.pub.tel.status[1:].any()  # the status area written (machine state, ...)
    desc = machine.describe()
    assert desc["daemon_telemetry"] == machine.pub.tel.name and desc["telemetry"] == u.tel.name


def test_a_hung_control_thread_is_found_once_safe_stopped_and_seen_to_tick_again(machine: Machine) -> None:
    u = machine.default
    u.start_control(no_realtime, 0)
    try:
        assert u.check_stall(time.monotonic_ns()) == ""  # it ticks
        u.loop.inject_hang(1.5)
        wait_for(lambda: u.check_stall(time.monotonic_ns()) or u.stalled, timeout_s=5.0)
        assert "has not ticked for" in u.stalled and "loop.py" in u.stalled, u.stalled  # where it waits
        assert u.check_stall(time.monotonic_ns()) == ""  # found once
        assert "still does not tick" in u.still_stalled()
        wait_for(lambda: u.resource.stopping_or_stopped)  # the unit's own thread stopped it
        wait_for(lambda: u.still_stalled() == "", timeout_s=5.0)  # the call returned: it ticks
        assert u.control_running()
    finally:
        u.stop()
        assert u.join(5.0) == []
