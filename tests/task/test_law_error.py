"""A law that raises is a type 3 exception (`LawError`) naming the module: the arm is safe-stopped
in that tick and the control loop goes on. And the case the soak found: a trajectory at its target
given a new speed limit does not ask Ruckig to plan from numerical residue."""

from __future__ import annotations

import types

import numpy as np
import pytest

from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.types import Phase, Status
from tests.conftest import MOVE_TASK, UR5E

FAR = [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_an_exception_in_a_module_is_a_type_3_that_safe_stops_and_the_loop_goes_on(compiled: bool) -> None:
    s = Session.open(UR5E)
    task = s.task(MOVE_TASK)
    loop = s.loop(SimClock())
    traj = next(m for m in task.modules if m.name == "traj")
    traj.configure({"target_rad": FAR})
    task.activate()
    loop.active = task
    loop.run_for(0.2)
    ct = next(m for m in task.modules if m.name == "ct")

    def broken(self: object, t_s: float) -> None:
        raise ZeroDivisionError("a user's module divided by zero")

    bound = types.MethodType(broken, ct)
    if compiled:  # the module's kernel raises, in the generated tick

        def broken_kernel(*args: object) -> tuple[object]:
            raise ZeroDivisionError("a user's module divided by zero")

        ct.kernel = lambda: broken_kernel  # type: ignore[method-assign]
        task.recompile()
    else:
        task.compiled = None
        task.schedule = tuple(bound if getattr(u, "__self__", None) is ct else u for u in task.schedule)
    ticks = loop.stats.ticks
    loop.run_for(0.5)  # the loop keeps ticking: the stop runs
    assert loop.stats.ticks > ticks + 100
    assert task.phase is Phase.FAULT
    assert "MoveJoints.T3.LawError" in s.event_names()
    assert task.fault_reason.startswith("LawError: MoveJoints.ct: ZeroDivisionError: a user")
    assert s.resource.state.status & (Status.STOPPING | Status.STOPPED)
    s.close()


def test_a_finished_trajectory_takes_a_new_speed_limit_without_replanning() -> None:
    s = Session.open(UR5E)
    task = s.task(MOVE_TASK)
    traj = next(m for m in task.modules if m.name == "traj")
    traj.configure({"target_rad": FAR})
    loop = s.loop(SimClock())
    assert loop.run_task(task, timeout_s=10.0) is Phase.DONE
    inp = traj._inp  # type: ignore[attr-defined]
    assert inp.current_position == FAR and not any(inp.current_velocity) and not any(inp.current_acceleration)
    for scale in (0.3, 0.9, 0.5):
        change = task.prepare_tune("traj.speed_scale", scale)
        task.apply_change(change)
        loop.run_for(0.05)
    assert task.phase is Phase.DONE
    assert np.allclose(traj.q_des.value, FAR)  # type: ignore[attr-defined]
    s.close()
