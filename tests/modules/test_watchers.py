"""Each watcher raises its event at the right tick (modules driven directly, no resource)."""

from __future__ import annotations

import numpy as np

from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.watchers import (
    ForceWatch,
    GraspMissedWatch,
    GraspWatch,
    JointLimitWatch,
    SignalAboveWatch,
    SignalBelowWatch,
    TargetReached,
    TimeoutWatch,
    TrackingErrorWatch,
)
from orccadd.robot import load_robot_config
from orccadd.state import JointState
from tests.conftest import UR5E

PERIOD_S = 0.002
MODEL = RobotModel.from_config(load_robot_config(UR5E))
CTX = ModuleContext("T", MODEL, PERIOD_S)


def first_fired(watcher, feed, n: int = 200) -> int | None:  # type: ignore[no-untyped-def]
    state = JointState(MODEL.dof)
    watcher.start(state)
    for k in range(n):
        feed(k)
        watcher.update(k * PERIOD_S)
        if bool(watcher.fired.value):
            return k
    return None


def test_tracking_error_fires_after_debounce() -> None:
    w = TrackingErrorWatch("w", CTX)
    w.configure({"threshold_rad": 0.05, "ticks": 3})

    def feed(k: int) -> None:
        w.q.value[:] = 0.0
        w.q_des.value[:] = 0.0
        w.q_des.value[4] = 0.01 * k  # crosses 0.05 at k = 6 (0.06 > 0.05)

    assert first_fired(w, feed) == 8  # k = 6, 7, 8 in a row


def test_joint_limit_fires_on_position_margin_and_on_speed() -> None:
    w = JointLimitWatch("w", CTX)
    w.configure({"margin_rad": 0.1, "velocity_fraction": 0.5})

    def feed_pos(k: int) -> None:
        w.q.value[:] = MODEL.home_rad
        w.q.value[2] = MODEL.q_max_rad[2] - 1.0 + 0.05 * k  # within 0.1 of the limit when k > 18
        w.dq.value[:] = 0.0

    assert first_fired(w, feed_pos) == 19

    def feed_speed(k: int) -> None:
        w.q.value[:] = MODEL.home_rad
        w.dq.value[:] = 0.0
        w.dq.value[0] = -0.1 * k  # 0.5 × 3.1415 = 1.57 exceeded at k = 16

    assert first_fired(w, feed_speed) == 16


def test_target_reached_needs_position_and_rest() -> None:
    w = TargetReached("w", CTX)
    w.configure({"tolerance_rad": 0.01, "velocity_tolerance_rad_s": 0.02, "ticks": 1})
    goal = MODEL.home_rad

    def feed(k: int) -> None:
        w.q_goal.value[:] = goal
        w.q.value[:] = goal + 0.1 * np.exp(-0.2 * k)  # within 0.01 from k = 12
        w.dq.value[:] = 0.05 if k < 20 else 0.0  # at rest from k = 20

    assert first_fired(w, feed) == 20


def test_timeout_fires_after_timeout_s() -> None:
    w = TimeoutWatch("w", CTX)
    w.configure({"timeout_s": 0.05})
    assert first_fired(w, lambda k: None) == 25  # 25 × 2 ms


def _closing(w, object_at: float | None):  # type: ignore[no-untyped-def]
    """A gripper closing from 0 to 0.6 rad at 1 rad/s with a 0.3 N.m limit; an object at
    `object_at` stops it there, pressing (None: nothing between the fingers)."""
    goal = np.full(MODEL.dof, 0.6)

    def feed(k: int) -> None:
        q = min(0.6, 0.01 * k)
        stopped = object_at is not None and q >= object_at
        q = object_at if stopped else q
        at_rest = stopped or q >= 0.6
        w.q_goal.value[:] = goal
        w.q.value[:] = q
        w.dq.value[:] = 0.0 if at_rest else 1.0
        w.tau.value[:] = 0.3 if stopped else 0.05  # the current limit reached only against it

    return feed


def test_grasp_watch_fires_at_rest_short_of_the_goal_pressing() -> None:
    w = GraspWatch("g", CTX)
    w.configure({"grip_torque_nm": 0.25, "ticks": 3})
    assert first_fired(w, _closing(w, object_at=0.3)) == 32  # at 0.3 from k = 30, 3 ticks in a row
    w = GraspWatch("g", CTX)
    w.configure({"grip_torque_nm": 0.25, "ticks": 3})
    assert first_fired(w, _closing(w, object_at=None)) is None  # closed on nothing


def test_grasp_missed_watch_fires_closed_on_nothing() -> None:
    w = GraspMissedWatch("m", CTX)
    w.configure({"grip_torque_nm": 0.25, "ticks": 3})
    assert first_fired(w, _closing(w, object_at=None)) == 62  # closed at k = 60
    w = GraspMissedWatch("m", CTX)
    w.configure({"grip_torque_nm": 0.25, "ticks": 3})
    assert first_fired(w, _closing(w, object_at=0.3)) is None  # holding something


def test_force_watch_fires_on_the_force_magnitude_and_optionally_the_torque() -> None:
    """A tool pressing into a surface: the force grows 1 N a tick along a slanted direction."""
    w = ForceWatch("f", CTX)
    w.configure({"force_n": 20.0, "ticks": 2})

    def feed(k: int) -> None:
        w.wrench.value[:] = [0.6 * k, 0.0, -0.8 * k, 3.0, 0.0, 0.0]  # |F| = k N; 3 N.m ignored

    assert first_fired(w, feed) == 22  # |F| > 20 from k = 21, two ticks in a row
    w = ForceWatch("f", CTX)
    w.configure({"force_n": 100.0, "torque_nm": 2.5})
    assert first_fired(w, feed) == 0  # the torque alone


def test_signal_below_fires_after_its_ticks_below_the_threshold_and_not_on_nan() -> None:
    w = SignalBelowWatch("w", CTX)
    w.configure({"threshold": 0.5, "ticks": 3})
    seen = [1.0, 0.0, 0.0, 1.0, float("nan"), 0.0, 0.0, 0.4, 0.0]  # a blink, a NaN, then lost

    def feed(k: int) -> None:
        w.inputs["value"].value[0] = seen[k] if k < len(seen) else 1.0

    assert first_fired(w, feed) == 7  # k = 5, 6, 7 in a row
    w.configure({"threshold": -1.0, "ticks": 1})  # any threshold, any sign
    assert first_fired(w, lambda k: w.inputs["value"].value.__setitem__(0, -2.0 if k == 4 else 0.0)) == 4


def test_signal_above_fires_after_its_ticks_at_or_above_the_threshold_and_not_on_nan() -> None:
    w = SignalAboveWatch("w", CTX)
    w.configure({"threshold": 0.5, "ticks": 3})
    seen = [0.0, 1.0, 1.0, 0.0, float("nan"), 1.0, 0.5, 1.0]  # a glimpse, a NaN, then seen

    def feed(k: int) -> None:
        w.inputs["value"].value[0] = seen[k] if k < len(seen) else 0.0

    assert first_fired(w, feed) == 7  # k = 5, 6, 7 in a row (0.5 counts: at or above)
