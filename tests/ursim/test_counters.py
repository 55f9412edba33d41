"""The counters the simulator keeps for benchmarks/ur_rtde_cycle.py (in `status()`): servoJ
updates per controller cycle, and the clock origin that maps a package's timestamp onto
CLOCK_MONOTONIC."""

from __future__ import annotations

import time

import numpy as np
import pytest

from orccadd.config.robot import RobotConfig
from orccadd.ursim.series import E_SERIES
from orccadd.ursim.simulator import UrSimulator
from tests.ursim.conftest import Clocked
from tests.ursim.test_controller import SERVOJ, start_script
from tests.ursim.test_protocol import EPHEMERAL

SERVOJ_INPUTS = ("input_int_register_0", *(f"input_double_register_{i}" for i in range(11)))


def servoj_package(c: Clocked, q: np.ndarray) -> None:
    """One RTDE input package of ur_rtde's servoJ, as the RTDE server applies it."""
    ctl = c.ctl
    with ctl.lock:
        ctl.state.in_int[0] = SERVOJ
        ctl.state.in_double[:11] = [*q, 0.0, 0.0, 0.002, 0.1, 300.0]
        ctl.inputs_written(SERVOJ_INPUTS)


def step(c: Clocked) -> None:
    c.t_s += c.ctl.period_s
    c.ctl.step(c.t_s)


def counts(c: Clocked) -> tuple[int, int, int]:
    ctl = c.ctl
    return ctl.servoj_cycles, ctl.servoj_stale_cycles, ctl.servoj_overwritten


def test_servoj_cycles_without_a_new_package_are_counted_and_doubled_packages_too(clocked: Clocked) -> None:
    c = clocked
    start_script(c.ctl)
    c.run(0.01)
    q = c.ctl.arm.q_rad.copy()
    assert counts(c) == (0, 0, 0)  # no servoj yet: nothing counted
    for _ in range(10):  # one package per cycle
        servoj_package(c, q)
        step(c)
    assert counts(c) == (10, 0, 0)
    step(c)  # a cycle without a package: the last target again
    assert counts(c) == (11, 1, 0)
    servoj_package(c, q)  # the late one and the next in the same cycle: one written over
    servoj_package(c, q)
    step(c)
    assert counts(c) == (12, 1, 1)
    with c.ctl.lock:  # servo_stop: no longer servoing, no longer counted
        c.ctl.state.in_int[0] = 16
        c.ctl.state.in_double[0] = 4.0
        c.ctl.inputs_written(("input_int_register_0", "input_double_register_0"))
    c.run(0.1)
    assert counts(c) == (12, 1, 1)


def test_status_reports_the_counters_and_the_clock_origin(ur5e: RobotConfig) -> None:
    s = UrSimulator(ur5e, E_SERIES, ports=EPHEMERAL, boot_running=True)
    assert s.status()["clock_origin_s"] is None  # before the first cycle
    t = time.monotonic()
    s.ctl.step(t)
    s.ctl.step(t + s.ctl.period_s)
    st = s.status()
    origin = st["clock_origin_s"]  # + a package's timestamp = its cycle's start on CLOCK_MONOTONIC
    assert origin + s.ctl.state.timestamp_s == pytest.approx(t + s.ctl.period_s, abs=1e-9)
    for key in ("servoj_cycles", "servoj_stale_cycles", "servoj_overwritten", "input_packages"):
        assert st[key] == 0
    assert st["missed_periods"] == 0 and st["rtde_packages_skipped"] == 0
