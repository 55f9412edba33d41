"""The execution machine's building blocks: clocks, real-time setup, periodic executor."""

from orccadd.runtime.clock import Clock, SimClock, WallClock
from orccadd.runtime.executor import PeriodicExecutor
from orccadd.runtime.rt import RealtimeReport, enter_realtime, leave_realtime
from orccadd.runtime.stats import Summary, TimingStats

__all__ = [
    "Clock",
    "PeriodicExecutor",
    "RealtimeReport",
    "SimClock",
    "Summary",
    "TimingStats",
    "WallClock",
    "enter_realtime",
    "leave_realtime",
]
