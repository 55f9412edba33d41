"""The force laws driven directly (no resource): the hybrid law moves the pose along its force
axes only, by the force error, at a bounded speed; the admittance settles where its spring
balances the push; the wrench estimated from joint torques is the one that made them; a force
setpoint above the tool's limit is refused."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from orccadd.errors import ParameterError
from orccadd.kinematics import ToolKinematics, quaternion_of, rotation_of
from orccadd.model import RobotModel
from orccadd.modules import ModuleContext
from orccadd.modules.force import Admittance, HybridForce, WrenchFromTorques
from orccadd.robot import load_robot_config
from orccadd.state import JointState
from tests.conftest import UR5E

PERIOD_S = 0.002
MODEL = RobotModel.from_config(load_robot_config(UR5E))
CTX = ModuleContext("T", MODEL, PERIOD_S)
HOME = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])


def at_home(module: HybridForce | Admittance) -> tuple[np.ndarray, np.ndarray]:
    """Started at HOME, its desired pose that of the tool there, at rest: that pose."""
    state = JointState(MODEL.dof)
    state.q_rad[:] = HOME
    module.begin(state)
    pose = ToolKinematics(MODEL).pose(HOME)
    module.inputs["position_des_m"].value[:] = pose.translation
    module.inputs["orientation_des"].value[:] = quaternion_of(pose.rotation)
    return pose.translation.copy(), pose.rotation.copy()


def test_the_hybrid_law_presses_along_its_force_axis_and_follows_the_trajectory_elsewhere() -> None:
    h = HybridForce("hf", CTX)
    h.configure(
        {"wrench_setpoint": [0.0, 0.0, 10.0, 0.0, 0.0, 0.0], "gain_m_s_n": 0.001, "max_speed_m_s": 0.02}
    )
    p0, r0 = at_home(h)
    h.inputs["position_des_m"].value[:] = p0 + np.array([0.05, 0.0, 0.3])  # the trajectory says up: not on z
    for k in range(100):  # 0.2 s pressing on nothing: down at 0.001 m/s/N * 10 N = 0.01 m/s
        h.update(k * PERIOD_S)
    p = h.outputs["position_ref_m"].value
    assert np.allclose(p[:2], p0[:2] + np.array([0.05, 0.0])) and np.isclose(p[2], p0[2] - 0.2 * 0.01)
    assert np.isclose(h.outputs["twist_ref"].value[2], -0.01)
    assert np.allclose(h.outputs["wrench_error"].value, [0, 0, 10, 0, 0, 0])
    assert np.allclose(rotation_of(h.outputs["orientation_ref"].value), r0)
    h.configure({"wrench_setpoint": [0.0, 0.0, 100.0, 0.0, 0.0, 0.0]})  # faster than allowed
    h.update(1.0)
    assert np.isclose(h.outputs["twist_ref"].value[2], -0.02)  # max_speed_m_s
    h.inputs["wrench"].value[:] = [0.0, 0.0, 100.0, 0.0, 0.0, 0.0]  # pressing as asked: stays
    z = float(h.outputs["position_ref_m"].value[2])
    h.update(1.002)
    assert np.isclose(h.outputs["position_ref_m"].value[2], z) and h.outputs["twist_ref"].value[2] == 0.0


def test_the_hybrid_laws_force_axes_may_be_the_tools() -> None:
    h = HybridForce("hf", CTX)
    # press along the tool's z with 10 N: the surface's reaction on the tool is -10 N on the tool's z
    h.configure({"wrench_setpoint": [0.0, 0.0, -10.0, 0.0, 0.0, 0.0], "in_tool_axes": 1, "gain_m_s_n": 0.001})
    p0, r0 = at_home(h)
    tool_z = r0[:, 2]  # pointing down at home
    # nothing touched yet: the tool moves along its own z, down, at 0.001 m/s/N * 10 N
    for k in range(50):
        h.update(k * PERIOD_S)
    moved = h.outputs["position_ref_m"].value - p0
    assert np.allclose(moved, 0.1 * 0.01 * tool_z, atol=1e-9) and moved[2] < 0.0
    h.inputs["wrench"].value[:] = [0.0, 0.0, 10.0, 0.0, 0.0, 0.0]  # pressed: +10 N on the base's z
    still = h.outputs["position_ref_m"].value.copy()
    h.update(1.0)
    assert np.allclose(h.outputs["position_ref_m"].value, still, atol=1e-12)


def test_the_admittance_gives_way_to_a_push_until_its_spring_balances_it() -> None:
    a = Admittance("adm", CTX)
    a.configure({"mass_kg": 1.0, "damping_n_s_m": 100.0, "stiffness_n_m": 1000.0})
    p0, _ = at_home(a)
    a.inputs["wrench"].value[:] = [10.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    for k in range(2000):  # 4 s: critically damped at 2·sqrt(k·m) = 63 N·s/m, this is over-damped
        a.update(k * PERIOD_S)
    assert np.allclose(a.outputs["position_ref_m"].value - p0, [0.01, 0.0, 0.0], atol=1e-5)  # 10 N / 1000 N/m
    assert np.allclose(a.outputs["twist_ref"].value, 0.0, atol=1e-5)
    a.inputs["wrench"].value[:] = 0.0
    for k in range(2000):
        a.update(4.0 + k * PERIOD_S)
    assert np.allclose(a.outputs["position_ref_m"].value, p0, atol=1e-5)  # and comes back


def test_the_wrench_from_torques_is_the_one_that_made_them() -> None:
    w_true = np.array([5.0, -3.0, 20.0, 0.5, -0.2, 0.1])
    q = HOME + np.array([0.1, 0.2, -0.3, 0.1, 0.4, 0.0])  # away from the wrist singularity
    kin = ToolKinematics(MODEL)
    kin.pose_and_jacobian(q)
    data = MODEL.new_data()
    # at rest: τ = g(q) − Jᵀ·W, the motors holding the arm against gravity and the world's wrench
    tau = pin.computeGeneralizedGravity(MODEL.model, data, q) - kin.jacobian.T @ w_true
    est = WrenchFromTorques("w", CTX)
    est.configure({"zero_at_start": 0})
    est.begin(JointState(MODEL.dof))
    est.inputs["q"].value[:], est.inputs["tau"].value[:] = q, tau
    est.update(0.0)
    assert np.allclose(est.outputs["wrench"].value, w_true, atol=1e-6)


def test_a_force_setpoint_above_the_tools_limit_is_refused() -> None:
    h = HybridForce("hf", CTX)
    with pytest.raises(
        ParameterError,
        match=r"hf.wrench_setpoint \(=\[0.0, 0.0, 150.0.*must be in \[-100, 100\] N\|N.m at index 2",
    ):
        h.configure({"wrench_setpoint": [0.0, 0.0, 150.0, 0.0, 0.0, 0.0]})
