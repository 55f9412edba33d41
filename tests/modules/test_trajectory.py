"""The Ruckig trajectory on a time base the resource's speed scaling slows (modules driven
directly, no resource)."""

from __future__ import annotations

import numpy as np

from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.trajectory import RuckigTrajectory, ScaledRuckigTrajectory
from orccadd.robot import load_robot_config
from orccadd.state import JointState
from tests.conftest import UR5E

PERIOD_S = 0.002
MODEL = RobotModel.from_config(load_robot_config(UR5E))
CTX = ModuleContext("T", MODEL, PERIOD_S)
TARGET = (MODEL.home_rad + 0.3).tolist()


def run(traj: RuckigTrajectory, scaling: list[float] | None = None, n: int = 5000) -> list[np.ndarray]:
    """Desired positions, velocities and accelerations tick by tick until `finished`."""
    state = JointState(MODEL.dof)
    state.q_rad[:] = MODEL.home_rad
    traj.configure({"target_rad": TARGET, "speed_scale": 0.5})
    traj.begin(state)
    rows = []
    for k in range(n):
        if isinstance(traj, ScaledRuckigTrajectory):
            traj.scaling.value[0] = scaling[k] if scaling is not None and k < len(scaling) else 1.0
        traj.update(k * PERIOD_S)
        rows.append(np.concatenate([traj.q_des.value, traj.dq_des.value, traj.ddq_des.value]))
        if bool(traj.finished.value):
            break
    return rows


def test_at_full_scaling_it_is_the_plain_trajectory() -> None:
    plain, scaled = run(RuckigTrajectory("p", CTX)), run(ScaledRuckigTrajectory("s", CTX), [1.0] * 5000)
    assert len(plain) == len(scaled) and np.array_equal(np.array(plain), np.array(scaled))


def test_at_half_scaling_it_takes_twice_as_long_at_half_the_speed() -> None:
    plain = np.array(run(RuckigTrajectory("p", CTX)))
    half = np.array(run(ScaledRuckigTrajectory("s", CTX), [0.5] * 10000, n=10000))
    n, dof = len(plain), MODEL.dof
    assert abs(len(half) - 2 * n) <= 2
    assert np.allclose(half[2 * (n // 2) - 1, :dof], plain[n // 2 - 1, :dof], atol=1e-9)  # same path
    assert np.abs(half[:, dof : 2 * dof]).max() == np.abs(plain[:, dof : 2 * dof]).max() / 2
    assert np.allclose(half[-1, :dof], TARGET)


def test_at_zero_it_holds_and_goes_on_from_there() -> None:
    scaling = [1.0] * 100 + [0.0] * 50 + [1.0] * 5000
    rows = np.array(run(ScaledRuckigTrajectory("s", CTX), scaling))
    dof = MODEL.dof
    held = rows[100:150]
    assert np.all(held[:, :dof] == rows[99, :dof]) and not held[:, dof:].any()  # still, at rest
    plain = np.array(run(RuckigTrajectory("p", CTX)))
    assert len(rows) == len(plain) + 50 and np.allclose(rows[150:, :dof], plain[100:, :dof])


def test_a_motion_at_a_profiles_boundary_is_planned_not_refused() -> None:
    """0.1 rad of a UR5e wrist at half speed: 5 rad/s², 50 rad/s³, d = 2a³/j² exactly, where
    Ruckig 0.19.4 raises "error in step 1" (`orccadctl jog --by 0.1` hit it: a type 3 LawError)."""
    traj = RuckigTrajectory("t", CTX)
    target = MODEL.home_rad.copy()
    target[3] += 0.1
    state = JointState(MODEL.dof)
    state.q_rad[:] = MODEL.home_rad
    traj.configure({"target_rad": target.tolist(), "speed_scale": 0.5})
    traj.begin(state)
    for k in range(1000):
        traj.update(k * PERIOD_S)
        assert traj.last_result.value >= 0, (k, traj.last_result)  # Working or Finished, never an error
        if bool(traj.finished.value):
            break
    assert bool(traj.finished.value) and np.allclose(traj.q_des.value, target)
