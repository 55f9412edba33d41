"""The task-space watchers fire at the right tick (driven directly, no resource)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.kinematics import quaternion_of
from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.cartesian_watchers import (
    ManipulabilityWatch,
    PlaneCrossed,
    PoseErrorWatch,
    PoseReached,
    WrenchSettled,
)
from orccadd.modules.watchers import Watcher
from orccadd.robot import load_robot_config
from orccadd.state import JointState
from tests.conftest import UR5E

PERIOD_S = 0.002
MODEL = RobotModel.from_config(load_robot_config(UR5E))
CTX = ModuleContext("T", MODEL, PERIOD_S)


def first_fired(watcher: Watcher, feed, n: int = 200) -> int | None:  # type: ignore[no-untyped-def]
    watcher.start(JointState(MODEL.dof))
    for k in range(n):
        feed(k)
        watcher.update(k * PERIOD_S)
        if bool(watcher.fired.value):
            return k
    return None


def test_a_pose_is_reached_near_the_goal_turned_as_it_and_at_rest() -> None:
    w = PoseReached("reached", CTX)
    w.configure({"tolerance_m": 0.001, "tolerance_rad": 0.01, "ticks": 3})
    goal_q = quaternion_of(pin.rpy.rpyToMatrix(np.pi, 0.0, 0.2))
    w.inputs["position_goal_m"].value[:] = [0.5, 0.0, 0.3]
    w.inputs["orientation_goal"].value[:] = goal_q

    def approach(k: int) -> None:  # 2 mm away, then 0.5 mm; turned 0.02 rad until tick 20
        w.inputs["position_m"].value[:] = [0.5 + (0.002 if k < 10 else 0.0005), 0.0, 0.3]
        w.inputs["orientation"].value[:] = quaternion_of(
            pin.rpy.rpyToMatrix(np.pi, 0.0, 0.2 + (0.02 if k < 20 else 0.005))
        )
        w.inputs["twist"].value[:] = [0.01 if k < 30 else 0.0, 0, 0, 0, 0, 0]  # moving until tick 30

    assert first_fired(w, approach) == 32  # 30, 31, 32: three ticks in a row


def test_a_pose_error_fires_on_distance_or_angle() -> None:
    w = PoseErrorWatch("lost", CTX)
    w.configure({"threshold_m": 0.01, "threshold_rad": 0.05, "ticks": 2})

    def drift(k: int) -> None:
        w.inputs["distance_m"].value[...] = 0.001 * k  # past 0.01 at tick 11
        w.inputs["angle_rad"].value[...] = 0.0

    assert first_fired(w, drift) == 12

    def turn(k: int) -> None:
        w.inputs["distance_m"].value[...] = 0.0
        w.inputs["angle_rad"].value[...] = 0.06 if k >= 5 else 0.0

    assert first_fired(w, turn) == 6


def test_manipulability_fires_below_its_threshold() -> None:
    w = ManipulabilityWatch("singular", CTX)
    w.configure({"threshold": 0.01})
    assert first_fired(w, lambda k: w.inputs["measure"].value.__setitem__(..., 0.05 - 0.001 * k)) == 41


def test_a_wrench_settles_when_its_error_stays_small() -> None:
    w = WrenchSettled("pressed", CTX)
    w.configure({"tolerance_n": 0.5, "ticks": 5})

    def press(k: int) -> None:  # the error falls 10 N -> 0 over 20 ticks; a torque error until 22
        w.inputs["wrench_error"].value[:] = [
            0.0,
            0.0,
            max(10.0 - 0.5 * k, 0.0),
            0.0,
            0.2 if k < 22 else 0.0,
            0.0,
        ]

    assert first_fired(w, press) == 26  # ticks 22-26


def test_a_plane_is_crossed_past_it_along_its_normal() -> None:
    w = PlaneCrossed("deep", CTX)
    w.configure({"point_m": [0.4, 0.1, 0.05], "normal": [0.0, 0.0, 1.0]})
    assert (
        first_fired(
            w, lambda k: w.inputs["position_m"].value.__setitem__(slice(None), [0.0, 0.0, 0.1 - 0.001 * k])
        )
        == 51
    )
    tilted = PlaneCrossed("beyond", CTX)
    tilted.configure({"point_m": [0.0, 0.0, 0.0], "normal": [1.0, 1.0, 0.0]})  # any length
    tilted.inputs["position_m"].value[:] = [0.1, -0.05, 5.0]
    assert first_fired(tilted, lambda k: None) is None
    tilted.inputs["position_m"].value[:] = [0.1, -0.15, 5.0]
    assert first_fired(tilted, lambda k: None) == 0
