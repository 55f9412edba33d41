"""IBVS driven directly: a pinhole camera on the tool, the module's desired pose taken as the
camera's (perfect tracking), converges on a square target seen off-centre and turned; holds
still while the target is not seen; the interaction matrix is the features' derivative."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.kinematics import ToolKinematics, rotation_of
from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.visual import ImageServo, interaction_matrix
from orccadd.robot import load_robot_config
from orccadd.state import JointState
from tests.conftest import UR5E

PERIOD_S = 0.002
MODEL = RobotModel.from_config(load_robot_config(UR5E))
CTX = ModuleContext("T", MODEL, PERIOD_S)
HOME = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
SIDE_M, DEPTH_M = 0.1, 0.3
HALF = SIDE_M / 2 / DEPTH_M  # the corners' normalised coordinates at the goal
GOAL = [-HALF, -HALF, HALF, -HALF, HALF, HALF, -HALF, HALF]


def project(points: np.ndarray, p: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The points' normalised image coordinates in a camera at (p, r) (z forward)."""
    cam = (points - p) @ r  # rᵀ·(P − p), row by row
    return (cam[:, :2] / cam[:, 2:3]).ravel()


def target_seen_from(p: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A square under the camera at (p, r), DEPTH_M ahead, its corners in GOAL's order."""
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * SIDE_M / 2
    return np.array([p + r @ np.array([x, y, DEPTH_M]) for x, y in corners])


def started(servo: ImageServo) -> tuple[np.ndarray, np.ndarray]:
    state = JointState(MODEL.dof)
    state.q_rad[:] = HOME
    servo.begin(state)
    pose = ToolKinematics(MODEL).pose(HOME)
    return pose.translation.copy(), pose.rotation.copy()


def test_the_camera_converges_on_a_target_seen_off_centre_and_turned() -> None:
    servo = ImageServo("vs", CTX)
    servo.configure({"features_des": GOAL, "gain": 2.0, "depth_m": DEPTH_M})
    p0, r0 = started(servo)
    # the camera's goal: 3 cm and 2 cm off, 5 cm nearer, turned 0.3 rad about its axis
    goal_p, goal_r = p0 + r0 @ np.array([0.03, -0.02, 0.05]), r0 @ pin.exp3(np.array([0.0, 0.0, 0.3]))
    points = target_seen_from(goal_p, goal_r)
    servo.inputs["visible"].value[...] = 1.0
    p, r = p0, r0
    for k in range(3000):  # 6 s at a gain of 2/s: e^-12
        servo.inputs["features"].value[:] = project(points, p, r)
        servo.update(k * PERIOD_S)
        p, r = (
            servo.outputs["position_des_m"].value.copy(),
            rotation_of(servo.outputs["orientation_des"].value),
        )
    assert float(servo.outputs["feature_error"].value) < 1e-4
    assert np.linalg.norm(p - goal_p) < 1e-3 and np.linalg.norm(pin.log3(r.T @ goal_r)) < 1e-3


def test_without_the_target_the_desired_pose_holds_still() -> None:
    servo = ImageServo("vs", CTX)
    servo.configure({"features_des": GOAL})
    p0, r0 = started(servo)
    servo.inputs["features"].value[:] = np.array(GOAL) + 0.1
    servo.inputs["visible"].value[...] = 0.0
    for k in range(100):
        servo.update(k * PERIOD_S)
    assert np.allclose(servo.outputs["position_des_m"].value, p0)
    assert np.allclose(servo.outputs["twist_des"].value, 0.0)
    assert np.allclose(rotation_of(servo.outputs["orientation_des"].value), r0)


def test_the_interaction_matrix_is_the_features_derivative() -> None:
    rng = np.random.default_rng(7)
    points = np.c_[rng.uniform(-0.1, 0.1, (4, 2)), np.full(4, 0.4)]  # in the camera's frame
    s = (points[:, :2] / points[:, 2:3]).ravel()
    twist = rng.normal(size=6) * 0.01
    h = 1e-6
    # the camera moving at `twist` (its own axes): a fixed point's coordinates change by -v - w x P
    moved = points - h * (twist[:3] + np.cross(twist[3:], points))
    ds = ((moved[:, :2] / moved[:, 2:3]).ravel() - s) / h
    lm = np.vstack([interaction_matrix(s[2 * i : 2 * i + 2], float(points[i, 2])) for i in range(4)])
    assert np.allclose(lm @ twist, ds, atol=1e-6)
