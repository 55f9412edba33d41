"""The control thread's side of the daemon: the slack handshake, the tune mailbox, a reset that
does not sleep in the automaton thread."""

from __future__ import annotations

import os
import select
import threading
import time

import numpy as np

from orccadd.daemon.machine import Machine
from orccadd.daemon.replies import Pending
from orccadd.types import Status
from orccadd.wire.schema import H, T


def test_slack_fd_becomes_readable_only_after_a_tick_ends(machine: Machine) -> None:
    loop = machine.default.loop
    control = threading.Thread(target=loop.executor.run, kwargs={"max_ticks": 2000})
    control.start()
    try:
        for _ in range(20):
            loop.want_slack()
            before = int(machine.default.tel.header[H.TICK_HEAD])
            ready, _, _ = select.select([loop.slack_fd], [], [], 1.0)
            assert ready
            assert int(machine.default.tel.header[H.TICK_HEAD]) > before  # a tick ended meanwhile
            os.read(loop.slack_fd, 64)
    finally:
        loop.executor.stop()
        control.join()


def test_slack_fd_stays_quiet_when_the_loop_is_stopped(machine: Machine) -> None:
    machine.default.loop.want_slack()
    ready, _, _ = select.select([machine.default.loop.slack_fd], [], [], 0.05)
    assert not ready


def test_a_tune_is_applied_at_one_tick_boundary_and_acknowledged_with_its_tick(machine: Machine) -> None:
    loop = machine.default.loop
    hold = loop.hold
    name, (_, param) = next((k, v) for k, v in hold._tunable.items() if v[1].tunable)
    new_value = param.value.copy() * 0.5 + 1.0
    seq = loop.tunes.post(hold.prepare_tune(name, new_value.tolist()))
    assert loop.tunes.acked(seq) is None
    assert not np.array_equal(param.value, new_value)  # waiting for the control thread
    loop.executor.run(max_ticks=1)
    tick = loop.tunes.acked(seq)
    assert tick == int(machine.default.tel.header[H.TICK_HEAD])  # the tick record of the tick it applied in
    assert np.array_equal(param.value, new_value)


def test_reset_is_a_pending_reply_and_never_sleeps(machine: Machine) -> None:
    loop = machine.default.loop
    loop.executor.run(max_ticks=5)
    machine.default.resource.inject_fault("device", "test fault")
    loop.executor.run(max_ticks=5)  # the fault → type 3 → safe stop from the control thread
    machine.on_events()
    assert machine.default.supervisor.fault
    res = machine.default.resource
    loop.executor.run(max_ticks=2000, until=lambda: bool(res.state.status & Status.STOPPED))
    t0 = time.monotonic()
    reply = machine.command("reset", {})
    assert time.monotonic() - t0 < 0.5  # no wait inside the command (order of magnitude only)
    end = time.monotonic() + 30.0
    while isinstance(reply, Pending) and reply.poll() is None:  # the device's reset: in a thread
        assert time.monotonic() < end, "the reset did not answer"
        loop.executor.run(max_ticks=1)
        time.sleep(0.001)
    assert not machine.default.supervisor.fault


def test_each_tick_record_holds_its_tick_field_by_field(machine: Machine) -> None:
    """The record is written through the block's memoryview, field by field at plain offsets:
    each field where `T` and the layout say, the header's counters where `H` says."""
    loop, res = machine.default.loop, machine.default.resource
    loop.set_task_ids({id(loop.hold): 7})  # (not 0: a field mistaken for another shows)
    loop.executor.run(max_ticks=30)
    task, stats, at = loop.active, loop.stats, loop.layout
    assert task is not None
    head = int(machine.default.tel.header[H.TICK_HEAD])
    rec = machine.default.tel.ticks[(head - 1) % machine.default.tel.tick_len]
    assert rec[T.SEQ] == head
    assert rec[T.T_S] == loop.executor._last_release_ns * 1e-9
    assert rec[T.WAKE_US] == stats.last_latency_ns * 1e-3
    assert rec[T.COMPUTE_US] == stats.last_compute_ns * 1e-3
    assert rec[T.TASK] == 7
    assert rec[T.PHASE] == task.phase
    assert rec[T.WROTE] == task.wrote
    assert rec[T.STATUS] == res.state.status
    assert rec[T.MODE] == res.mode
    assert rec[at.q].tolist() == res.state.q_rad.tolist()
    assert rec[at.dq].tolist() == res.state.dq_rad_s.tolist()
    assert rec[at.tau].tolist() == res.state.tau_nm.tolist()
    assert rec[at.cmd].tolist() == res.last_command.tolist()
    for name, where in at.signals.items():
        assert rec[where].tolist() == res.signals[name].tolist()
    hdr = machine.default.tel.header
    assert (hdr[H.TICKS], hdr[H.SWITCHES]) == (stats.ticks, loop.switches) == (30, 1)
    assert (hdr[H.OVERRUNS], hdr[H.CONSECUTIVE_OVERRUNS]) == (stats.overruns, stats.consecutive_overruns)
