"""Shared fixtures: the UR5e behind the simulated controller, in this process (unit tests) or
as its own process that stock ur_rtde talks to (the `stock` tests)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from orccadd.config.robot import RobotConfig, read_robot_config
from orccadd.ursim.arm import UrArm
from orccadd.ursim.controller import UrController
from orccadd.ursim.series import E_SERIES, Series
from tests.conftest import ROOT

UR5E_RTDE = ROOT / "configs" / "robots" / "ur5e-rtde-sim.toml"


@pytest.fixture(scope="session")
def ur5e() -> RobotConfig:
    return read_robot_config(UR5E_RTDE)


def make_controller(cfg: RobotConfig, series: Series = E_SERIES, unlock_delay_s: float = 0.0) -> UrController:
    """A controller booted running, stepped by the test (`Clocked.run`)."""
    return UrController(UrArm(cfg, 1.0 / series.rate_hz, {}), series, unlock_delay_s, boot_running=True)


class Clocked:
    """Steps a controller on simulated time (no sleeping: as fast as the CPU allows)."""

    def __init__(self, ctl: UrController) -> None:
        self.ctl = ctl
        self.t_s = 1000.0
        ctl.clock = lambda: self.t_s

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / self.ctl.period_s)):
            self.t_s += self.ctl.period_s
            self.ctl.step(self.t_s)


@pytest.fixture
def clocked(ur5e: RobotConfig) -> Iterator[Clocked]:
    yield Clocked(make_controller(ur5e))


# ---- stock ur_rtde against the simulator as its own process ------------------------------------
# ur_rtde reaches a controller on fixed ports: every simulator started through `UrSimProcess`
# holds a machine-wide lock on them (orccadd.ursim.process.PortsLock), so tests of two pytest
# runs, or of orccadd's own suites, never meet on them. ur_rtde's calls block in C++ holding
# the interpreter: these tests time out with pytest-timeout's thread method, which can end a
# process stuck in one.
STOCK_TIMEOUT = pytest.mark.timeout(90, method="thread")


def wait_until(predicate: Callable[[], bool], timeout_s: float = 10.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} not reached in {timeout_s:g} s")
        time.sleep(0.01)


def distinct_timestamps(r: Any, seconds: float) -> list[float]:
    """The controller timestamps an RTDEReceiveInterface shows over `seconds`, each once."""
    seen: set[float] = set()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        seen.add(r.getTimestamp())
        time.sleep(0.0002)
    return sorted(seen)
