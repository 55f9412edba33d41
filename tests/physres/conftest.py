"""These tests run the control loop in the test's own thread: at real-time priority, as the
daemon runs its loop, so that a busy machine (another process beside `make test`) delays it no
more than it would the daemon's. Below the simulators' (70): they are the hardware."""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator
from typing import Any

import pytest

from orccadd.runtime.rt import fifo_priority

LOOP_PRIORITY = 50


@pytest.fixture(autouse=True)
def loop_at_realtime_priority(request: pytest.FixtureRequest) -> Iterator[None]:
    # no reset-on-fork: the threads the resource starts (a bus's reader, a periodic heartbeat)
    # inherit it, as they would run beside a real-time loop; a simulator the test starts raises
    # its own priority. A module may opt out (`LOOP_AT_REALTIME = False`): the Dynamixel SDK
    # polls its port in a busy loop, which at real-time priority keeps the kernel's tty worker
    # (time-shared) from delivering the answer it waits for.
    if not getattr(request.module, "LOOP_AT_REALTIME", True) or not fifo_priority(LOOP_PRIORITY):
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


# ---- tests that apply to a backend, from its description ---------------------------------
DESCRIBED_BY = {  # the config each backend's description is read from at collection
    "sim": "configs/robots/sim-ur5e.toml",
    "sim_process": "configs/robots/sim-ur5e.toml",
    "canopen402": "configs/robots/canopen-6axis.toml",
    "dynamixel": "configs/robots/dxl-6axis-sim.toml",
    "ur_rtde": "configs/robots/ur5e-rtde-sim.toml",
    "ethercat402": "configs/robots/ethercat-6axis-sim.toml",
}


def _modes(backend: str) -> frozenset[Any]:
    from orccadd.robot import backend_class, load_robot_config, with_backend
    from tests.conftest import ROOT

    with contextlib.redirect_stderr(io.StringIO()):  # its config's warnings: said where it runs
        cfg = load_robot_config(ROOT / DESCRIBED_BY[backend])
    if cfg.resource.backend != backend:
        cfg = with_backend(cfg, backend)
    return frozenset(backend_class(backend, cfg.source).describe(cfg).modes)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """`@pytest.mark.applies(mode=M)` (or `mode="param"`: the test's own parameter): a test in a
    command mode its backend does not declare does not apply, and is not run (deselected, not
    skipped): the contract suite is generated from the descriptions."""
    keep, dropped, modes = [], [], {}
    for item in items:
        mark = item.get_closest_marker("applies")
        params = getattr(getattr(item, "callspec", None), "params", {})
        backend = params.get("resource")
        if mark is None or backend is None:
            keep.append(item)
            continue
        want = mark.kwargs["mode"]
        mode = params[want] if isinstance(want, str) else want
        if backend not in modes:
            modes[backend] = _modes(backend)
        (keep if mode in modes[backend] else dropped).append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = keep
