"""Per-tick timing samples in preallocated arrays, summarised off the hot path."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Summary:
    """Order statistics of one quantity, in microseconds."""

    median_us: float
    p99_us: float
    p999_us: float
    max_us: float

    @staticmethod
    def of(samples_ns: np.ndarray) -> Summary:
        if samples_ns.size == 0:
            return Summary(0.0, 0.0, 0.0, 0.0)
        us = samples_ns / 1000.0
        q = np.percentile(us, [50, 99, 99.9])
        return Summary(float(q[0]), float(q[1]), float(q[2]), float(us.max()))

    def line(self) -> str:
        return (
            f"median {self.median_us:8.1f}  p99 {self.p99_us:8.1f}  "
            f"p99.9 {self.p999_us:8.1f}  max {self.max_us:8.1f} µs"
        )


class TimingStats:
    """Wake-up latency, compute time, release period and overruns of a periodic task.

    The release period is the time between two ticks' releases: exactly the period (times the
    periods skipped) on our own deadlines, the device's cycle as we saw it on a device-paced loop.

    `record` is tick-safe (writes into preallocated arrays; keeps the last `capacity` ticks).
    """

    def __init__(self, period_s: float, capacity: int = 120_000) -> None:
        self.period_s = period_s
        self._lat = np.zeros(capacity, dtype=np.int64)
        self._cmp = np.zeros(capacity, dtype=np.int64)
        self._per = np.zeros(capacity, dtype=np.int64)
        self._over = np.zeros(capacity, dtype=np.bool_)
        self._cap = capacity
        self.ticks = 0
        self._first = 0  # `ticks` before the first recorded here (`continue_from`)
        self.overruns = 0
        self.missed_ticks = 0
        self.consecutive_overruns = 0
        self.max_consecutive_overruns = 0
        self.last_latency_ns = 0
        self.last_compute_ns = 0

    def record(
        self, latency_ns: int, compute_ns: int, overrun: bool, missed: int, period_ns: int = 0
    ) -> None:
        self.last_latency_ns = latency_ns
        self.last_compute_ns = compute_ns
        i = self.ticks % self._cap
        self._lat[i] = latency_ns
        self._cmp[i] = compute_ns
        self._per[i] = period_ns
        self._over[i] = overrun
        self.ticks += 1
        self.missed_ticks += missed
        if overrun:
            self.overruns += 1
            self.consecutive_overruns += 1
            if self.consecutive_overruns > self.max_consecutive_overruns:
                self.max_consecutive_overruns = self.consecutive_overruns
        else:
            self.consecutive_overruns = 0

    def continue_from(self, ticks: int, overruns: int) -> None:
        """Count on from another's counts (a resource's unit started again in a new process: its
        telemetry's counters go on); the figures are this one's ticks only."""
        self.ticks = self._first = ticks
        self.overruns = overruns

    def _window(self, arr: np.ndarray) -> np.ndarray:
        recorded = self.ticks - self._first
        if recorded >= self._cap:
            return arr
        start = self._first % self._cap
        return np.roll(arr, -start)[:recorded]

    @property
    def latency(self) -> Summary:
        return Summary.of(self._window(self._lat))

    @property
    def compute(self) -> Summary:
        return Summary.of(self._window(self._cmp))

    @property
    def release_period(self) -> Summary:
        """Between successive releases (the first tick has none: 0)."""
        return Summary.of(self._window(self._per)[1:])

    def overrun_runs(self) -> dict[int, int]:
        """How many runs of consecutive overruns of each length (in the recorded window)."""
        runs: dict[int, int] = {}
        n = 0
        for flag in [*self._window(self._over).tolist(), False]:
            if flag:
                n += 1
            elif n:
                runs[n] = runs.get(n, 0) + 1
                n = 0
        return runs

    def latencies_ns(self) -> np.ndarray:
        return self._window(self._lat).copy()

    def report(self, name: str = "loop") -> str:
        return "\n".join(
            [
                f"{name}: {self.ticks} ticks at {self.period_s * 1e3:g} ms, "
                f"{self.overruns} overruns (max {self.max_consecutive_overruns} in a row), "
                f"{self.missed_ticks} missed periods",
                f"  wake-up latency  {self.latency.line()}",
                f"  compute time     {self.compute.line()}",
                f"  release period   {self.release_period.line()}",
            ]
        )
