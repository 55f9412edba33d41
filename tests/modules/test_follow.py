"""The trajectory follower's spline and module (driven directly, no resource): through every
point, C2, at rest at both ends; its limit check agrees with a dense sampling of the motion."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.errors import ParameterError
from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.follow import MAX_POINTS, JointTrajectory, JointTrajectoryFollow, Spline, first_excess
from orccadd.robot import load_robot_config
from orccadd.state import JointState
from tests.conftest import UR5E

PERIOD_S = 0.002
MODEL = RobotModel.from_config(load_robot_config(UR5E))
CTX = ModuleContext("T", MODEL, PERIOD_S)
LIMITS = (MODEL.q_min_rad, MODEL.q_max_rad, MODEL.v_max_rad_s, MODEL.a_max_rad_s2)


def uneven(n: int = 9, seed: int = 3) -> JointTrajectory:
    """`n` points at uneven times over about a second, near home, 0.1 rad apart at most."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.2, n - 1))])
    q = MODEL.home_rad + np.cumsum(rng.uniform(-0.1, 0.1, (n, MODEL.dof)), axis=0)
    return JointTrajectory(t, q)


def test_the_spline_passes_every_point_is_c2_and_at_rest_at_both_ends() -> None:
    traj = uneven()
    sp = Spline(traj)
    q, dq, _ = sp.at(traj.t_s)
    np.testing.assert_allclose(q, traj.q_rad, atol=1e-12)
    assert not dq[0].any() and np.abs(dq[-1]).max() < 1e-12
    # each segment's end meets the next one's start: position, velocity, acceleration
    h = sp.h[:-1]
    ends = (
        sp.c0[:-1] + h * (sp.c1[:-1] + h * (sp.c2[:-1] + h * sp.c3[:-1])),
        sp.c1[:-1] + h * (2 * sp.c2[:-1] + 3 * h * sp.c3[:-1]),
        2 * sp.c2[:-1] + 6 * h * sp.c3[:-1],
    )
    for end, start in zip(ends, (sp.c0[1:], sp.c1[1:], 2 * sp.c2[1:]), strict=True):
        np.testing.assert_allclose(end, start, rtol=1e-9, atol=1e-9)


def test_velocity_and_acceleration_are_the_positions_derivatives() -> None:
    sp = Spline(uneven())
    t = np.linspace(0.0, float(sp.t_s[-1]), 4001)
    q, dq, ddq = sp.at(t)
    np.testing.assert_allclose(np.gradient(q, t, axis=0)[1:-1], dq[1:-1], atol=2e-3)
    # the jerk steps at the points: a central difference there is off by about jerk·dt
    np.testing.assert_allclose(np.gradient(dq, t, axis=0)[2:-2], ddq[2:-2], atol=0.2)


def test_the_check_finds_what_a_dense_sampling_finds() -> None:
    sp = Spline(uneven())
    t = np.linspace(0.0, float(sp.t_s[-1]), 200_001)
    q, dq, ddq = sp.at(t)
    v_peak, a_peak = np.abs(dq).max(axis=0), np.abs(ddq).max(axis=0)
    q_min, q_max = q.min(axis=0), q.max(axis=0)
    assert first_excess(sp, q_min - 1e-9, q_max + 1e-9, v_peak * 1.0001, a_peak * 1.0001) is None
    j = int(np.argmax(v_peak))
    e = first_excess(
        sp, q_min - 1e-9, q_max + 1e-9, v_peak * 1.0001 - np.eye(MODEL.dof)[j] * 1e-3 * v_peak, a_peak * 2
    )
    assert e is not None and (e.quantity, e.joint) == ("velocity", j)
    assert e.value == pytest.approx(v_peak[j], rel=1e-6)
    k = int(np.searchsorted(sp.t_s, t[np.argmax(np.abs(dq[:, j]))], side="right") - 1)
    assert e.row == k and e.between  # on the way from point k to k + 1


def test_an_overshoot_between_points_is_a_position_excess() -> None:
    # up and back down, unevenly: the spline rises above the highest point after it
    t = np.array([0.0, 0.3, 1.0])
    q = np.tile(MODEL.home_rad, (3, 1))
    q[1, 0] += 0.4
    sp = Spline(JointTrajectory(t, q))
    top = float(sp.at(np.linspace(0, 1, 10001))[0][:, 0].max())
    assert top > q[1, 0]  # past the point itself
    q_max = MODEL.q_max_rad.copy()
    q_max[0] = q[1, 0] + 1e-6  # every point within, the motion beyond
    fast = np.full(MODEL.dof, 1e6)  # only positions matter here
    e = first_excess(sp, MODEL.q_min_rad, q_max, fast, fast)
    assert e is not None and (e.row, e.quantity, e.joint, e.between) == (1, "position", 0, True)
    assert e.value == pytest.approx(top, abs=1e-6)


def test_a_point_out_of_range_is_named_where_the_motion_first_leaves_the_range() -> None:
    traj = uneven()
    fast = np.full(MODEL.dof, 1e6)  # only positions matter here
    q = traj.q_rad.copy()
    q[4, 2] = MODEL.q_max_rad[2] + 0.5  # reached from point 3: on the way there
    e = first_excess(Spline(JointTrajectory(traj.t_s, q)), MODEL.q_min_rad, MODEL.q_max_rad, fast, fast)
    assert e is not None and (e.row, e.joint, e.quantity, e.between) == (3, 2, "position", True)
    assert MODEL.q_max_rad[2] < e.value and e.limit == MODEL.q_max_rad[2]
    q = traj.q_rad.copy()
    q[0, 1] = MODEL.q_min_rad[1] - 0.1  # the first point itself
    e = first_excess(Spline(JointTrajectory(traj.t_s, q)), MODEL.q_min_rad, MODEL.q_max_rad, fast, fast)
    assert e is not None and (e.row, e.joint, e.quantity, e.between) == (0, 1, "position", False)
    assert e.value == q[0, 1] and e.limit == MODEL.q_min_rad[1]


def test_the_module_plays_the_spline_tick_by_tick_and_ends_at_the_last_point() -> None:
    traj = uneven()
    m = JointTrajectoryFollow("traj", CTX)
    assert m.needs_data()
    m.set_data(traj)
    assert not m.needs_data()
    state = JointState(MODEL.dof)
    state.q_rad[:] = traj.q_rad[0]
    m.begin(state)
    t0, rows = 10.0, []  # the law's first tick is the trajectory's time 0, whatever the clock says
    for k in range(int(traj.t_s[-1] / PERIOD_S) + 5):
        m.update(t0 + k * PERIOD_S)
        rows.append((k * PERIOD_S, m.q_des.value.copy(), m.dq_des.value.copy(), bool(m.finished.value)))
        if rows[-1][3]:
            break
    assert rows[-1][3] and not rows[-2][3]
    np.testing.assert_array_equal(rows[-1][1], traj.q_rad[-1])
    np.testing.assert_array_equal(m.q_goal.value, traj.q_rad[-1])
    t = np.array([r[0] for r in rows[:-1]])
    q, dq, _ = Spline(traj).at(t)
    np.testing.assert_allclose(np.array([r[1] for r in rows[:-1]]), q, atol=1e-9)
    np.testing.assert_allclose(np.array([r[2] for r in rows[:-1]]), dq, atol=1e-9)


def test_data_that_is_not_a_trajectory_of_this_arm_is_refused() -> None:
    m = JointTrajectoryFollow("traj", CTX)
    with pytest.raises(ParameterError, match="takes a JointTrajectory"):
        m.set_data([1, 2, 3])
    with pytest.raises(ParameterError, match="one row of 6"):
        m.set_data(JointTrajectory(np.array([0.0, 1.0]), np.zeros((2, 3))))
    with pytest.raises(ParameterError, match="increase strictly from 0"):
        m.set_data(JointTrajectory(np.array([0.0, 1.0, 1.0]), np.zeros((3, 6))))
    assert "2 to" in JointTrajectory(np.zeros(1), np.zeros((1, 6))).problem(6)
    assert str(MAX_POINTS) in JointTrajectory(np.zeros(1), np.zeros((1, 6))).problem(6)
    assert m.needs_data()
