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


def test_a_result_code_the_ruckig_binding_lacks_holds_the_last_desired_position() -> None:
    """Ruckig 0.19.4's Python enum has no -101 (trajectory duration beyond its limits): the binding
    raises ValueError from `update`, seen after `speed_scale` 1.0 then 0.01 mid-motion. That is
    Ruckig failing to plan, not the law failing: the hold branch, never a LawError."""
    s = Session.open(UR5E)
    task = s.task(MOVE_TASK)
    traj = next(m for m in task.modules if m.name == "traj")
    traj.configure({"target_rad": FAR})
    loop = s.loop(SimClock())
    task.activate()
    loop.active = task
    loop.run_for(0.3)

    class Duration:  # the real binding's failure mode, on demand
        def update(self, inp: object, out: object) -> object:
            raise ValueError("-101 is not a valid Result")

    traj._otg = Duration()  # type: ignore[attr-defined]
    task.recompile()
    held = traj.q_des.value.copy()  # type: ignore[attr-defined]
    loop.run_for(0.5)
    assert "MoveJoints.T3.LawError" not in s.event_names(), s.event_names()
    assert task.phase is Phase.RUN and not s.resource.state.status & (Status.STOPPING | Status.STOPPED)
    assert np.allclose(traj.q_des.value, held) and not traj.dq_des.value.any()  # type: ignore[attr-defined]
    s.close()
