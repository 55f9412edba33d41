"""The documented example module works inside a task built from a file."""

from __future__ import annotations

import numpy as np

from orccadd.runtime import SimClock
from orccadd.session import Session
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
    loop.run_for(0.4)
    dq = s.resource.state.dq_rad_s
    assert np.abs(lp.y.value).max() > 0.0  # follows the motion...
    assert np.abs(lp.y.value).max() < np.abs(dq).max() + 1.0  # ...smoothed, bounded
    assert lp._a == 2.0 * np.pi * 2.0 * 0.002  # the tune reached on_parameter_change
