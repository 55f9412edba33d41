"""A loop's timing statistics: counted on from another's (a unit started again in a new process),
its figures are its own ticks only, wherever they fall in the ring."""

from __future__ import annotations

from orccadd.runtime.stats import TimingStats


def test_counts_go_on_from_anothers_and_the_figures_are_this_ones_ticks() -> None:
    s = TimingStats(0.001, capacity=8)
    s.continue_from(ticks=13, overruns=2)  # 13 % 8: the ring's sixth slot first
    for us in (10, 20, 30):
        s.record(us * 1000, 5000, overrun=us == 30, missed=0)
    assert s.ticks == 16 and s.overruns == 3
    assert s.latency.max_us == 30.0 and s.latency.median_us == 20.0  # no empty slot counted
    for _ in range(10):  # past the ring's size: its last eight
        s.record(40_000, 5000, overrun=False, missed=0)
    assert s.latency.median_us == 40.0 and s.ticks == 26
