"""The reactive shell: preconditions, T1 local reaction, T2, T3 → safe stop, tuning."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from orccadd.errors import ParameterError
from orccadd.runtime import SimClock
from orccadd.session import Session
from orccadd.types import Phase, Status
from tests.conftest import MOVE_TASK, UR5E

FAR = [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]


def open_task(path=MOVE_TASK):  # type: ignore[no-untyped-def]
    s = Session.open(UR5E)
    task = s.task(path)
    return s, task, s.loop(SimClock())


def test_t1_lowers_speed_locally_and_task_completes(task_variant) -> None:  # type: ignore[no-untyped-def]
    s, task, loop = open_task(task_variant(("threshold_rad = 0.02", "threshold_rad = 0.002")))
    traj = next(m for m in task.modules if m.name == "traj")
    traj.configure({"target_rad": FAR})
    assert loop.run_task(task, timeout_s=10.0) is Phase.DONE
    names = s.event_names()
    assert names[:2] == ["MoveJoints.pre", "MoveJoints.T1.TrackingDrift"] and names[-1] == "MoveJoints.done"
    assert float(traj.speed_scale.value) == pytest.approx(0.4)


def test_t2_aborts_and_keeps_commanding(task_variant) -> None:  # type: ignore[no-untyped-def]
    s, task, loop = open_task(task_variant(("threshold_rad = 0.2", "threshold_rad = 0.003")))
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    assert loop.run_task(task, timeout_s=10.0) is Phase.ABORTED
    assert "MoveJoints.T2.TrackingLost" in s.event_names()
    assert not s.resource.stopping_or_stopped  # the procedure decides what next; law still runs
    before = task.command.copy()
    loop.run_for(0.05)
    assert not np.array_equal(before, task.command)


def test_precondition_timeout_is_a_type_2(task_variant) -> None:  # type: ignore[no-untyped-def]
    s, task, loop = open_task(task_variant(("max_abs_below = 0.5", "within = [5.0, 6.0]")))
    t0 = s.resource.state.t_s
    assert loop.run_task(task, timeout_s=5.0) is Phase.PRE_FAILED
    ((t_event, eid),) = s.queue.drain()
    assert s.registry.info(eid).name == "MoveJoints.T2.PreconditionTimeout"
    assert t_event - t0 == pytest.approx(1.0 + 0.002, abs=0.0021)  # timeout_s = 1.0
    assert "ArmSlow" in task.fault_reason


def check_stopped_safely(s: Session, loop, category_torque_off: bool) -> None:  # type: ignore[no-untyped-def]
    res = s.resource
    period, a = s.config.control_period_s, s.config.safe_stop.deceleration_rad_s2
    speeds = [res.state.dq_rad_s.copy()]
    for _ in range(1500):  # 3 s
        loop.executor.run(max_ticks=1)
        speeds.append(res.state.dq_rad_s.copy())
    speeds_arr = np.array(speeds)
    assert np.abs(speeds_arr[-50:]).max() < 0.01
    # The stop follows a velocity ramp at the configured deceleration `a` (the drive's servo adds
    # a short transient at its start, ~1.5 a here): never twice as hard ...
    decel = np.abs(np.diff(speeds_arr, axis=0)).max() / period
    assert decel < 2 * a, decel
    # ... nor twice as gentle: each joint still moving comes to rest in about |v| / a.
    v0 = speeds_arr[0]
    for j in np.flatnonzero(np.abs(v0) > 0.1):
        rest_s = (np.flatnonzero(np.abs(speeds_arr[:, j]) >= 1e-3)[-1] + 1) * period
        assert 0.67 < rest_s * a / abs(v0[j]) < 1.5, (j, v0[j], rest_s)
    q = res.state.q_rad
    assert ((q >= res.model.q_min_rad) & (q <= res.model.q_max_rad)).all()
    assert res.state.status & Status.STOPPED
    assert bool(res.state.status & Status.TORQUE_OFF) is category_torque_off


def test_t3_from_a_watcher_safe_stops_the_arm(task_variant) -> None:  # type: ignore[no-untyped-def]
    s, task, loop = open_task(
        task_variant(("margin_rad = 0.02", "margin_rad = 0.02\nvelocity_fraction = 0.3"))
    )
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    assert loop.run_task(task, timeout_s=10.0) is Phase.FAULT
    assert s.event_names() == ["MoveJoints.pre", "MoveJoints.T3.NearJointLimit"]
    assert s.resource.stopping_or_stopped
    assert np.abs(s.resource.state.dq_rad_s).max() > 0.5  # it was moving fast
    check_stopped_safely(s, loop, category_torque_off=True)  # category 1: brakes, torque off


def test_resource_fault_is_a_type_3() -> None:
    s, task, loop = open_task()
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    task.activate()
    loop.active = task
    loop.run_for(0.3)
    s.resource.inject_fault("device", "over-current on axis 2")
    loop.run_for(0.01)
    assert task.phase is Phase.FAULT
    assert "MoveJoints.T3.ResourceFault" in s.event_names()
    check_stopped_safely(s, loop, category_torque_off=True)


def test_tune_is_checked_before_anything_changes() -> None:
    _, task, _ = open_task()
    ct = next(m for m in task.modules if m.name == "ct")
    with pytest.raises(ParameterError, match=r"ct.kp \(=-3\) must be in \[0, 100000\]"):
        task.prepare_tune("ct.kp", -3)
    with pytest.raises(ParameterError, match="has no parameter 'ct.gain'"):
        task.prepare_tune("ct.gain", 1.0)
    with pytest.raises(ParameterError, match=r"has no parameter 'ct.kpp'; did you mean ct\.kp"):
        task.prepare_tune("ct.kpp", 1.0)  # a typo gets the nearest names
    with pytest.raises(ParameterError, match="must be 6 numbers"):
        task.prepare_tune("ct.kp", [1.0, 2.0])
    change = task.prepare_tune("ct.kp", 500.0)
    assert float(ct.kp.value[0]) == 900.0  # checked, not applied
    task.apply_change(change)
    assert (ct.kp.value == 500.0).all()


def test_one_element_of_a_vector_is_tuned_alone() -> None:
    _, task, _ = open_task()
    ct = next(m for m in task.modules if m.name == "ct")
    change = task.prepare_tune("ct.kp[2]", 650.0)
    other = task.prepare_tune("ct.kp[4]", 350)  # checked before the first is applied
    task.apply_change(change)
    task.apply_change(other)  # writes its element only: the first stays
    assert ct.kp.value.tolist() == [900.0, 900.0, 650.0, 900.0, 350.0, 900.0]
    with pytest.raises(ParameterError, match=r"must be in \[0, 100000\] 1/s\^2 at index 2"):
        task.prepare_tune("ct.kp[2]", -1.0)
    with pytest.raises(ParameterError, match="has indices 0 to 5"):
        task.prepare_tune("ct.kp[6]", 1.0)
    with pytest.raises(ParameterError, match=r"an element is named PARAM\[i\]"):
        task.prepare_tune("ct.kp[-1]", 1.0)
    with pytest.raises(ParameterError, match="must be one number"):
        task.prepare_tune("ct.kp[1]", [1.0])
    assert ct.kp.value.tolist() == [900.0, 900.0, 650.0, 900.0, 350.0, 900.0]


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_a_law_that_outputs_nan_is_a_type_3_and_nothing_is_sent(compiled: bool) -> None:
    s, task, loop = open_task()
    ct = next(m for m in task.modules if m.name == "ct")
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    task.activate()
    loop.active = task
    loop.run_for(0.3)
    law = ct.update
    if compiled:  # the module's kernel outputs the NaN, in the generated tick
        kernel = ct.kernel()

        def broken_kernel(*args: Any) -> tuple[list[float]]:
            (tau,) = kernel(*args)
            return ([*tau[:2], float("nan"), *tau[3:]],)

        ct.kernel = lambda: broken_kernel  # type: ignore[method-assign]
        task.recompile()
    else:

        def broken_law(t_s: float) -> None:  # a module bug: a NaN in the torque it outputs
            law(t_s)
            ct.tau.value[2] = np.nan

        task.compiled = None
        task.schedule = tuple(broken_law if u == law else u for u in task.schedule)
    loop.run_for(0.01)
    assert task.phase is Phase.FAULT
    assert "MoveJoints.T3.LimitViolation" in s.event_names()
    assert s.resource.rejected_count == 1  # the first one: then the safe stop ignores commands
    check_stopped_safely(s, loop, category_torque_off=True)
    assert np.isfinite(s.resource.state.vector).all()


def test_a_task_that_runs_past_its_timeout_is_a_type_3(task_variant) -> None:  # type: ignore[no-untyped-def]
    s, task, loop = open_task(task_variant(('command = "torque"', 'command = "torque"\ntimeout_s = 0.2')))
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    assert loop.run_task(task, timeout_s=10.0) is Phase.FAULT
    assert s.event_names() == ["MoveJoints.pre", "MoveJoints.T3.Timeout"]
    assert "ran 0.2 s" in task.fault_reason
    check_stopped_safely(s, loop, category_torque_off=True)


def test_timeouts_default_to_the_robots_and_inf_means_none(task_variant) -> None:  # type: ignore[no-untyped-def]
    _, task, _ = open_task()
    assert task.timeout_s == 300.0 and "Timeout" in task.signature.t3  # sim-ur5e's default
    _, forever, _ = open_task(task_variant(('command = "torque"', 'command = "torque"\ntimeout_s = inf')))
    assert forever.timeout_s == float("inf") and "Timeout" not in forever.signature.t3
