"""The periodic control thread's body: tick the active Robot-Task, or just measure when idle."""

from __future__ import annotations

from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import ClockSource
from orccadd.runtime.clock import Clock, DevicePacedClock, WallClock
from orccadd.runtime.executor import PeriodicExecutor
from orccadd.runtime.stats import TimingStats
from orccadd.task.task import RobotTask
from orccadd.types import Phase

SETTLED = (Phase.DONE, Phase.ABORTED, Phase.FAULT, Phase.PRE_FAILED)


def resource_clock(resource: PhysicalResource, spin_margin_s: float = 0.0) -> Clock:
    """The clock that releases `resource`'s ticks, from its description: our own deadlines on
    CLOCK_MONOTONIC, or the device's cycle (`wait_for_cycle`) for a device-paced resource."""
    if resource.description.clock is ClockSource.DEVICE:
        return DevicePacedClock(resource.wait_for_cycle, resource.config.control_period_s)
    return WallClock(spin_margin_s=spin_margin_s)


class ControlLoop:
    """Runs one resource's active task every control period on `clock`.

    `overrun_limit` overruns in a row raise the active task's type 3 exception `Overrun`
    (which safe-stops the resource from this thread).
    """

    def __init__(self, resource: PhysicalResource, clock: Clock, *, overrun_limit: int = 3) -> None:
        self.resource = resource
        self.active: RobotTask | None = None
        self.overrun_limit = overrun_limit
        period = resource.config.control_period_s
        self.executor = PeriodicExecutor(
            clock,
            period,
            self.step,
            on_overrun=self._on_overrun,
            stats=TimingStats(period),
            after_step=self.after_step,
        )

    @property
    def stats(self) -> TimingStats:
        return self.executor.stats

    def step(self, t_s: float) -> None:
        """One control period (tick)."""
        task = self.active
        if task is None:
            self.resource.read(t_s)  # idle: the resource holds; keep measuring
            self.resource.keep_alive(t_s)
        else:
            task.tick(t_s)

    def after_step(self, t_s: float) -> None:
        """After each tick, its timing recorded (`stats.last_*` are this tick's); default: nothing."""

    def _on_overrun(self, t_s: float, consecutive: int) -> None:
        if consecutive >= self.overrun_limit and self.active is not None:
            why = f"the control thread missed {consecutive} deadlines in a row (limit {self.overrun_limit})"
            self.active.raise_t3(t_s, "Overrun", why)

    def run_task(self, task: RobotTask, timeout_s: float) -> Phase:
        """Activate `task` and tick until it settles (done, T2, T3, precondition failure) or
        `timeout_s` of loop time passes. The task stays active (holding) afterwards."""
        self.active = task
        task.activate()
        max_ticks = max(1, int(round(timeout_s / (self.executor.period_ns * 1e-9))))
        self.executor.run(max_ticks=max_ticks, until=lambda: task.phase in SETTLED)
        return task.phase

    def run_for(self, duration_s: float) -> None:
        """Keep ticking the active task (or idling) for `duration_s` of loop time."""
        self.executor.run(max_ticks=max(1, int(round(duration_s / (self.executor.period_ns * 1e-9)))))
