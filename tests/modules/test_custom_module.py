"""The documented example module works inside a task built from a file."""

from __future__ import annotations

import numpy as np

from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.types import Phase
from tests.conftest import UR5E


def test_low_pass_example_in_a_task(task_variant) -> None:  # type: ignore[no-untyped-def]
    path = task_variant(
        ('"arm.dq -> limits.dq",', '"arm.dq -> lp.x",\n  "lp.y -> limits.dq",'),
        ("[modules.limits]", '[modules.lp]\ntype = "low_pass"\ncutoff_hz = 5.0\n\n[modules.limits]'),
    )
    s = Session.open(UR5E)
    task = s.task(path)
    lp = next(m for m in task.modules if m.name == "lp")
    assert [m.name for m in task.modules].index("lp") < [m.name for m in task.modules].index("limits")
    task.tune("lp.cutoff_hz", 2.0)
    task.activate()
    loop = s.loop(SimClock())
    loop.active = task
    tick = loop.executor.step
    xs, ys, running = [], [], []

    def step(t_s: float) -> None:
        tick(t_s)
        xs.append(s.resource.state.dq_rad_s.copy())  # what lp.x read this tick (arm.dq)
        ys.append(lp.y.value.copy())
        running.append(task.phase is Phase.RUN)

    loop.executor.step = step
    loop.run_for(0.4)
    a = 2.0 * np.pi * 2.0 * 0.002  # the tuned cutoff, 2 Hz, at the 2 ms period
    assert lp._a == a  # the tune reached on_parameter_change
    # every tick of the run, y moved toward the measured speed by the first-order filter's step
    pairs = [k for k in range(1, len(ys)) if running[k - 1] and running[k]]
    assert len(pairs) > 100
    for k in pairs:
        np.testing.assert_allclose(ys[k], ys[k - 1] + a * (xs[k] - ys[k - 1]), rtol=0, atol=1e-12)
    # it follows the motion, smoothed: lagging behind the arm as it speeds up
    k = pairs[-1]
    assert np.abs(ys[k]).max() > 0.05
    assert np.abs(ys[k]).max() < np.abs(xs[k]).max()
