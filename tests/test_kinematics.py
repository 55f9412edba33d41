"""The tool's kinematics: its frame from `[tool]`, the Jacobian against finite differences of the
pose, the task error's log map, damped least squares near a singularity."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from orccadd.config.robot import ToolConfig
from orccadd.kinematics import (
    ToolKinematics,
    angle_between,
    damped_pseudo_inverse,
    manipulability,
    pose_error,
    quaternion_of,
    rotate_back,
    rotation_error,
    rotation_of,
    smallest_singular_value,
)
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from tests.conftest import PANDA, UR5E

HOME = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])


def ur5e(tool: ToolConfig | None = None) -> RobotModel:
    """sim-ur5e's model, with `tool` for its [tool] (None: the config's, the flange tool0)."""
    cfg = load_robot_config(UR5E)
    return RobotModel.from_config(replace(cfg, tool=tool) if tool is not None else cfg)


def test_the_tool_is_the_configured_frame_and_offset() -> None:
    plain = ToolKinematics(ur5e(ToolConfig())).pose(HOME)  # no [tool]: the last joint's link
    model = ur5e()
    data = model.new_data()
    pin.framesForwardKinematics(model.model, data, HOME)
    link = data.oMf[model.model.getFrameId("wrist_3_link")]
    assert np.allclose(plain.translation, link.translation) and np.allclose(plain.rotation, link.rotation)
    tool = ToolConfig(frame="tool0", offset_m=(0.0, 0.0, 0.1), offset_rpy_rad=(0.0, 0.0, np.pi / 2))
    tipped = ToolKinematics(ur5e(tool)).pose(HOME)
    flange = data.oMf[model.model.getFrameId("tool0")]
    # 0.1 m along tool0's z (pointing down at home), turned a quarter about it
    assert np.allclose(tipped.translation, flange.translation + 0.1 * flange.rotation[:, 2], atol=1e-9)
    assert np.isclose(angle_between(flange.rotation, tipped.rotation), np.pi / 2)
    assert tipped.translation[2] < flange.translation[2] - 0.099  # the tool points down at home
    shipped = ToolKinematics(model).pose(HOME)  # sim-ur5e's [tool]: the flange, 0.1 m below the link
    assert (
        np.allclose(shipped.translation, flange.translation)
        and link.translation[2] - 0.0996 < shipped.translation[2] + 1e-3
    )


@pytest.mark.parametrize("config", [UR5E, PANDA])
def test_the_jacobian_is_the_derivative_of_the_pose(config) -> None:  # type: ignore[no-untyped-def]
    model = RobotModel.from_config(load_robot_config(config))
    kin = ToolKinematics(model)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(np.maximum(model.q_min_rad, -3.0), np.minimum(model.q_max_rad, 3.0))
        p0 = kin.pose_and_jacobian(q).copy()
        jac = kin.jacobian.copy()
        h = 1e-6
        for i in range(model.dof):
            dq = np.zeros(model.dof)
            dq[i] = h
            p1 = kin.pose(q + dq)
            linear = (p1.translation - p0.translation) / h
            angular = pin.log3(p1.rotation @ p0.rotation.T) / h  # base axes, as the Jacobian's
            assert np.allclose(jac[:3, i], linear, atol=1e-5), (i, jac[:3, i], linear)
            assert np.allclose(jac[3:, i], angular, atol=1e-5), (i, jac[3:, i], angular)


def test_quaternions_round_trip_with_a_positive_w() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        r = pin.exp3(rng.normal(size=3))
        quat = quaternion_of(r)
        assert quat[3] >= 0.0 and np.isclose(np.linalg.norm(quat), 1.0)
        assert np.allclose(rotation_of(quat), r)
    assert np.allclose(rotation_of([0.0, 0.0, 0.0, 2.0]), np.eye(3))  # normalised


def test_the_pose_error_is_the_displacement_and_the_rotation_vector_toward_the_goal() -> None:
    r = pin.rpy.rpyToMatrix(0.1, -0.2, 0.3)
    turn = pin.exp3(np.array([0.0, 0.0, 0.4]))  # 0.4 rad about the base's z
    e = pose_error(np.array([1.0, 2.0, 3.0]), r, np.array([1.5, 2.0, 2.0]), turn @ r)
    assert np.allclose(e, [0.5, 0.0, -1.0, 0.0, 0.0, 0.4])
    assert np.isclose(angle_between(r, turn @ r), 0.4)


def test_damped_least_squares_is_the_pseudo_inverse_away_from_singularities_and_bounded_at_one() -> None:
    model = ur5e()
    kin = ToolKinematics(model)
    kin.pose_and_jacobian(HOME)
    j = kin.jacobian.copy()
    assert smallest_singular_value(j) > 0.05 and manipulability(j) > 1e-3
    assert np.allclose(damped_pseudo_inverse(j, 0.0), np.linalg.pinv(j), atol=1e-8)
    wrist_aligned = HOME.copy()
    wrist_aligned[4] = 0.0  # wrists 1 and 3 on one axis: the UR's wrist singularity
    kin.pose_and_jacobian(wrist_aligned)
    singular = kin.jacobian.copy()
    assert smallest_singular_value(singular) < 1e-6 and manipulability(singular) < 1e-6
    damping = 0.05
    # at most 1/(2·damping) rad/s per unit of task velocity, whichever the direction
    assert np.linalg.norm(damped_pseudo_inverse(singular, damping), 2) <= 1.0 / (2.0 * damping) + 1e-9


def test_the_error_on_quaternions_is_the_log_map_of_the_matrices() -> None:
    rng = np.random.default_rng(11)
    for _ in range(50):
        r, r_des = pin.exp3(rng.normal(size=3) * 2.0), pin.exp3(rng.normal(size=3) * 2.0)
        q, q_des = quaternion_of(r), quaternion_of(r_des)
        scaled = [2.0 * v for v in q]  # not unit: normalised first
        assert np.allclose(rotation_error(scaled, q_des), pin.log3(r_des @ r.T), atol=1e-9)
        v = rng.normal(size=3)
        assert np.allclose(rotate_back(q, v.tolist()), r.T @ v, atol=1e-12)
    assert rotation_error([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]) == [0.0, 0.0, 0.0]
