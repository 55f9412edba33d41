"""A tick allocates no buffers: steady-state memory does not grow over a thousand ticks."""

from __future__ import annotations

import tracemalloc

from orccadd.runtime import SimClock
from orccadd.session import Session
from tests.conftest import MOVE_TASK, UR5E


def test_ticks_do_not_grow_memory() -> None:
    s = Session.open(UR5E)
    task = s.task(MOVE_TASK)
    loop = s.loop(SimClock(), overrun_limit=10**6)
    next(m for m in task.modules if m.name == "traj").configure(
        {"target_rad": [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]}
    )
    task.activate()
    loop.active = task
    loop.run_for(0.1)  # warm up (first-call caches)
    s.queue.drain()
    tracemalloc.start()
    before, _ = tracemalloc.get_traced_memory()
    loop.run_for(2.0)  # 1000 ticks of motion
    after, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert after - before < 20_000, after - before  # < 20 bytes a tick: nothing kept per tick
