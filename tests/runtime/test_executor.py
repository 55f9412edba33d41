"""The periodic executor: absolute deadlines, overrun counting, T3 after N overruns in a row."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.runtime import PeriodicExecutor, SimClock, TimingStats, WallClock
from orccadd.runtime.stats import Summary
from orccadd.session import Session
from orccadd.types import Phase
from tests.conftest import MOVE_TASK, UR5E


def test_sim_clock_ticks_on_exact_deadlines() -> None:
    clock = SimClock(start_s=1.0)
    times: list[float] = []
    ex = PeriodicExecutor(clock, 0.001, times.append)
    assert ex.run(max_ticks=100) == 100
    np.testing.assert_allclose(np.diff(times), 0.001, atol=1e-12)
    assert times[0] == pytest.approx(1.001)
    assert ex.stats.overruns == 0 and ex.stats.latency.max_us == 0.0
    ex.run(max_ticks=10)  # deadlines continue across calls
    assert times[-1] == pytest.approx(1.110)


def test_overruns_are_counted_and_missed_periods_skipped() -> None:
    clock = SimClock()
    calls: list[float] = []
    overruns: list[int] = []

    def step(t_s: float) -> None:
        calls.append(t_s)
        if len(calls) in (5, 6, 7):
            clock.advance(0.0025)  # this tick takes 2.5 periods

    ex = PeriodicExecutor(clock, 0.001, step, on_overrun=lambda t, n: overruns.append(n))
    ex.run(max_ticks=20)
    assert ex.stats.overruns == 3
    assert ex.stats.max_consecutive_overruns == 3
    assert overruns == [1, 2, 3]
    assert ex.stats.missed_ticks == 6  # two periods skipped each time, never run in a burst
    assert all(round(d * 1e3) >= 1 for d in np.diff(calls))


def test_consecutive_overruns_raise_type_3_and_safe_stop() -> None:
    s = Session.open(UR5E)
    task = s.task(MOVE_TASK)
    clock = SimClock()
    loop = s.loop(clock, overrun_limit=3)
    inner = loop.executor.step

    def slow(t_s: float) -> None:
        inner(t_s)
        if t_s > 0.2:
            clock.advance(0.003)

    loop.executor.step = slow
    assert loop.run_task(task, timeout_s=2.0) is Phase.FAULT
    assert "MoveJoints.T3.Overrun" in s.event_names()
    assert s.resource.stopping_or_stopped


def test_wall_clock_keeps_the_period() -> None:
    period = 0.002
    clock = WallClock()
    releases: list[float] = []
    ex = PeriodicExecutor(clock, period, releases.append)
    t0 = clock.now_ns()
    assert ex.run(max_ticks=25) == 25
    elapsed_s = (clock.now_ns() - t0) * 1e-9
    st = ex.stats
    assert st.ticks == 25
    # Releases lie on the absolute deadline grid: whole periods apart, a gap longer than one
    # period only where periods were skipped (and counted) after an overrun.
    gaps = np.diff(releases) / period
    np.testing.assert_allclose(gaps, np.round(gaps), atol=1e-6)
    skipped = int(np.round(gaps).sum()) - len(gaps)
    assert np.round(gaps).min() >= 1
    assert skipped <= st.missed_ticks and (skipped == 0 or st.overruns > 0)
    # The wall clock never wakes before its deadline, and usually well within the period.
    lat = st.latencies_ns()
    assert lat.size == 25 and lat.min() >= 0
    assert st.latency.median_us < period * 1e6
    # Run time: the ticks plus the periods skipped, never early; above, an order of magnitude
    # only (a stall of this shared VM after the last tick is counted nowhere)
    assert elapsed_s >= 25 * period
    assert elapsed_s < 10 * (25 + st.missed_ticks) * period, (elapsed_s, st.report())


def test_summary_statistics() -> None:
    s = Summary.of(np.arange(1, 1001) * 1000)
    assert s.median_us == 500.5 and s.max_us == 1000.0 and 990 <= s.p99_us <= 991
    st = TimingStats(0.001, capacity=10)
    for i in range(25):
        st.record(i, i, False, 0)
    assert st.ticks == 25 and st.latency.max_us == 0.024
