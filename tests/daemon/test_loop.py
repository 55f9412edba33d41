"""The control thread's slack handshake: client work waits for the end of a tick."""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator

import pytest

from orccadd.config import load_robot_config, with_backend
from orccadd.daemon.machine import Machine
from orccadd.daemon.telemetry import H, Layout, TelemetryBlock
from orccadd.physres import create_resource
from orccadd.physres.base import CommandMode
from orccadd.runtime import WallClock
from tests.daemon.conftest import ROBOT


@pytest.fixture
def machine() -> Iterator[Machine]:
    cfg = with_backend(load_robot_config(ROBOT), "sim")
    res = create_resource(cfg)
    res.configure()
    res.activate(CommandMode.TORQUE)
    tel = TelemetryBlock.create(Layout(cfg.dof, 1000, 100), cfg.control_period_s)
    r, w = os.pipe2(os.O_NONBLOCK)
    m = Machine(cfg, res, WallClock(), tel, w)
    try:
        yield m
    finally:
        tel.close()
        res.shutdown()
        os.close(r)
        os.close(w)


def test_wait_for_slack_returns_after_a_tick_ends(machine: Machine) -> None:
    loop = machine.loop
    control = threading.Thread(target=loop.executor.run, kwargs={"max_ticks": 2000})
    control.start()
    try:
        for _ in range(20):
            before = int(machine.tel.header[H.TICK_HEAD])
            assert loop.wait_for_slack(timeout_s=1.0)
            assert int(machine.tel.header[H.TICK_HEAD]) > before  # a tick ended meanwhile
    finally:
        loop.executor.stop()
        control.join()


def test_wait_for_slack_times_out_when_the_loop_is_stopped(machine: Machine) -> None:
    assert not machine.loop.wait_for_slack(timeout_s=0.05)
