"""A tick allocates nothing it keeps: measured tick by tick over the steady state.

Per tick, tracemalloc gives the memory the tick left behind (kept) and its transient peak. In
the steady state (after the first ticks' caches), no tick keeps an array or grows a list: the
kept bytes are zero up to the interpreter's free-list noise (a few bytes, both signs), and the
numpy data domain does not change at all. The transient peak (temporary Python objects such as
the lists the watchers compare) is printed and bounded by an order of magnitude only.
"""

from __future__ import annotations

import tracemalloc

import numpy as np

from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.types import Phase
from tests.conftest import MOVE_TASK, UR5E

NUMPY_DOMAIN = np.lib.tracemalloc_domain
STEADY_TICKS = 400


def test_no_tick_keeps_memory_in_the_steady_state() -> None:
    s = Session.open(UR5E)
    task = s.task(MOVE_TASK)
    loop = s.loop(SimClock(), overrun_limit=10**6)
    next(m for m in task.modules if m.name == "traj").configure(
        {"target_rad": [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]}
    )
    task.activate()
    loop.active = task
    loop.run_for(0.2)  # warm up: first-call caches, the trajectory under way
    s.queue.drain()
    run = loop.executor.run
    tracemalloc.start()
    try:
        kept = np.zeros(STEADY_TICKS, dtype=np.int64)  # preallocated: the probe keeps nothing itself
        peaks = np.zeros(STEADY_TICKS, dtype=np.int64)
        run(max_ticks=20)  # tracemalloc's own first traces
        numpy_before = _numpy_bytes()
        for i in range(STEADY_TICKS):
            tracemalloc.reset_peak()
            before = tracemalloc.get_traced_memory()[0]
            run(max_ticks=1)
            after, peak = tracemalloc.get_traced_memory()
            kept[i] = after - before
            peaks[i] = peak - before
        numpy_after = _numpy_bytes()
    finally:
        tracemalloc.stop()
    assert task.phase in (Phase.RUN, Phase.DONE)  # the law ran every tick (DONE keeps it running)
    print(
        f"per tick: kept max {max(kept)} B, sum {sum(kept)} B; transient peak median {np.median(peaks):.0f} B"
    )
    assert numpy_after == numpy_before  # no array data kept by any tick
    # one 6-joint array alone would keep more than 150 bytes; below that, the float free list's
    # churn (floats of one tick freed in the next) shows up to 88 B in a tick, never in the sum
    assert max(kept) <= 128, kept
    assert abs(sum(kept)) <= 256, sum(kept)  # 1 byte a tick kept would show here
    assert np.median(peaks) < 64_000  # order of magnitude: temporaries, not buffers


def _numpy_bytes() -> int:
    snap = tracemalloc.take_snapshot().filter_traces([tracemalloc.DomainFilter(True, NUMPY_DOMAIN)])
    return sum(t.size for t in snap.traces)
