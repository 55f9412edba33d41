"""Periodic execution on absolute deadlines with an injected clock.

Each tick is released by the clock: on our own clocks at the deadline (`t0 + k·period`, so
sleeping never accumulates drift), on a device-paced clock when the device's cycle arrives (the
next deadline then follows that release). A tick that ends after the next deadline is an
overrun; missed periods are skipped (never run in a burst) and counted. Wake-up latency (from
release to the step's start), compute time and the period between releases are measured the
same way for both. `on_overrun(consecutive)` lets the owner raise a type 3 exception after N
overruns in a row.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from orccadd.runtime.clock import Clock
from orccadd.runtime.stats import TimingStats


class PeriodicExecutor:
    """Calls `step(t_s)` every `period_s` on `clock`; `t_s` is the nominal release time."""

    def __init__(
        self,
        clock: Clock,
        period_s: float,
        step: Callable[[float], None],
        *,
        on_overrun: Callable[[float, int], None] | None = None,
        stats: TimingStats | None = None,
        after_step: Callable[[float], None] | None = None,
    ) -> None:
        self.clock = clock
        self.period_ns = int(round(period_s * 1e9))
        self.step = step
        self.on_overrun = on_overrun
        self.after_step = after_step  # once the tick's timing is recorded (e.g. to publish it)
        self.stats = stats if stats is not None else TimingStats(period_s)
        self._next_ns: int | None = None
        self._last_release_ns = 0
        self._stop = False

    def stop(self) -> None:
        """Ask the loop to return after the current tick (any thread, any time)."""
        self._stop = True

    def run(self, max_ticks: int | None = None, until: Callable[[], bool] | None = None) -> int:
        """Run ticks until `max_ticks`, `until()` is true after a tick, or `stop()`.

        Deadlines continue across successive calls. Returns the number of ticks run.
        """
        clock, period, step, stats = self.clock, self.period_ns, self.step, self.stats
        perf = time.perf_counter_ns
        if self._next_ns is None:
            self._next_ns = clock.now_ns() + period
        self._stop = False
        n = 0
        last_release = self._last_release_ns
        while not self._stop and (max_ticks is None or n < max_ticks):
            release = clock.wait_release_ns(self._next_ns)
            woke = clock.now_ns()
            c0 = perf()
            step(release * 1e-9)
            c1 = perf()
            end = clock.now_ns()  # on a SimClock only `advance()` inside a step makes time pass
            nxt = release + period
            missed = 0
            if end > nxt:
                missed = (end - nxt) // period + 1
                nxt += missed * period
            overrun = missed > 0
            since = release - last_release if last_release else 0
            stats.record(woke - release, c1 - c0, overrun, int(missed), since)
            last_release = self._last_release_ns = release
            self._next_ns = nxt
            if self.after_step is not None:
                self.after_step(release * 1e-9)
            n += 1
            if overrun and self.on_overrun is not None:
                self.on_overrun(release * 1e-9, stats.consecutive_overruns)
            if until is not None and until():
                break
        return n
