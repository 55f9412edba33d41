"""The velocity guard (`orccadd.physres.guard`): no in-bounds gains can drive a joint past its
velocity limit in torque mode; commands that keep within it go through untouched."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from orccadd.model import RobotModel
from orccadd.physres.guard import VelocityGuard
from orccadd.robot import load_robot_config
from orccadd.runtime import SimClock
from orccadd.session import Session
from tests.conftest import MOVE_TASK, UR5E

# in-bounds, and as hostile to the limits as the bounds allow: a huge integral gain with its
# widest clamp, no damping, full speed, the joint-limit watcher at its highest threshold
HOSTILE = {
    "ct.ki": 1e6,
    "ct.integral_limit_rad_s": 10.0,
    "ct.kd": 0.0,
    "traj.speed_scale": 1.0,
    "limits.velocity_fraction": 1.0,
}


@pytest.mark.parametrize(
    "target", [[2.5, -0.5, 0.5, -0.5, 2.5, 3.0], [-2.5, -2.5, 2.5, -2.5, -2.5, -3.0]], ids=["out", "back"]
)
def test_in_bound_gains_never_carry_a_joint_past_its_velocity_limit(target: list[float]) -> None:
    """Before the guard: up to 1.26 × max_velocity (kd = 0), the safe stop too late to prevent it."""
    s = Session.open(UR5E)
    try:
        task = s.task(MOVE_TASK)
        for path, value in HOSTILE.items():
            module, param = path.split(".")
            next(m for m in task.modules if m.name == module).configure({param: value})
        next(m for m in task.modules if m.name == "traj").configure({"target_rad": target})
        loop = s.loop(SimClock())
        v_max = s.resource.model.v_max_rad_s
        ratio: list[float] = []

        def step(t_s: float) -> None:
            task.tick(t_s)
            ratio.append(float((np.abs(s.resource.state.dq_rad_s) / v_max).max()))

        loop.executor.step = step
        loop.run_task(task, timeout_s=5.0)
        assert max(ratio) <= 1.0, (target, max(ratio), s.event_names())
        assert not any("LimitViolation" in e for e in s.event_names()), s.event_names()
        assert int(s.resource.diagnostics().details["velocity_guard_cuts"]) > 0
    finally:
        s.close()


def test_the_guard_passes_what_keeps_within_and_cuts_the_rest_to_the_horizon() -> None:
    model = RobotModel.from_config(load_robot_config(UR5E))
    period_s = 0.002
    guard = VelocityGuard(model, period_s)
    data = model.new_data()
    rng = np.random.default_rng(7)
    for _ in range(200):
        q = rng.uniform(model.q_min_rad, model.q_max_rad)
        dq = rng.uniform(-1.05, 1.05) * model.v_max_rad_s * rng.uniform(0, 1, model.dof)
        tau = rng.uniform(-1, 1, model.dof) * model.tau_max_nm
        cut = guard.limit(q, dq, tau)
        out = tau.tolist() if cut is None else cut
        ddq = pin.aba(model.model, data, q, dq, np.array(out))
        lo = (-model.v_max_rad_s - dq) / (2 * period_s)
        hi = (model.v_max_rad_s - dq) / (2 * period_s)
        if cut is None:  # untouched: it kept within
            assert np.all((ddq >= lo - 1e-6) & (ddq <= hi + 1e-6))
        else:  # cut: within the box unless the torque limit forbids it, and never beyond max torque
            assert np.all(np.abs(out) <= model.tau_max_nm + 1e-9)
            saturated = np.abs(np.abs(out) - model.tau_max_nm) < 1e-9
            if not saturated.any():
                assert np.all((ddq >= lo - 1e-6) & (ddq <= hi + 1e-6)), (ddq, lo, hi)


def test_the_guard_passes_exactly_what_the_box_test_on_arrays_passes() -> None:
    """The tick tests the box on Python floats: the same verdict as on numpy arrays, joints on
    its edges and NaN included (the cut path aside, which keeps the arrays)."""
    model = RobotModel.from_config(load_robot_config(UR5E))
    period_s = 0.001
    guard = VelocityGuard(model, period_s)
    data = model.new_data()
    h = guard.horizon_s
    rng = np.random.default_rng(11)
    for k in range(300):
        q = rng.uniform(model.q_min_rad, model.q_max_rad)
        dq = rng.uniform(-1.0, 1.0, model.dof) * model.v_max_rad_s
        tau = rng.uniform(-1, 1, model.dof) * model.tau_max_nm * rng.uniform(0, 0.3)
        if k % 3 == 0:  # a joint near an edge of the box
            j = k % model.dof
            dq[j] = model.v_max_rad_s[j] - pin.aba(model.model, data, q, dq, tau)[j] * h
        if k % 50 == 1:
            tau[k % model.dof] = np.nan
        ddq = pin.aba(model.model, data, q, dq, tau)
        lo, hi = (-model.v_max_rad_s - dq) / h, (model.v_max_rad_s - dq) / h
        passes = bool(np.all((ddq >= lo) & (ddq <= hi)))
        assert (guard.limit(q, dq, tau) is None) == passes
