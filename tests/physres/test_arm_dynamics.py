"""The one arm-dynamics core: free fall, friction that really sticks, brakes, hard stops."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.model import RobotModel
from orccadd.physres.arm_dynamics import ArmDynamics
from orccadd.robot import load_robot_config
from tests.conftest import UR5E

H = 0.0005


def model() -> RobotModel:
    return RobotModel.from_config(load_robot_config(UR5E))


def arm(**kw) -> ArmDynamics:  # type: ignore[no-untyped-def]
    m = model()
    n = m.dof
    args = {"viscous_nm_s_rad": np.zeros(n), "coulomb_nm": np.zeros(n), **kw}
    return ArmDynamics(m, m.home_rad, **args)


def run(a: ArmDynamics, seconds: float, tau: np.ndarray | None = None) -> None:
    tau = np.zeros(a.dof) if tau is None else tau
    for k in range(int(seconds / H)):
        if k % 10 == 0:
            a.refresh_inertia()
        a.step(tau, H)


def test_without_torque_and_friction_the_arm_falls_and_conserves_energy() -> None:
    a = arm()
    m, d = a.pin_model, a.data
    e0 = pin.computePotentialEnergy(m, d, a.q)
    run(a, 0.2)
    assert np.abs(a.dq).max() > 0.1  # it falls
    e1 = pin.computePotentialEnergy(m, d, a.q) + pin.computeKineticEnergy(m, d, a.q, a.dq)
    assert abs(e1 - e0) < 0.02 * abs(e0) + 0.5  # semi-implicit Euler: energy nearly kept


def test_gravity_torque_holds_the_arm_still() -> None:
    a = arm()
    q0 = a.q.copy()
    for _ in range(400):
        a.step(a.gravity_nm().copy(), H)
    assert np.abs(a.q - q0).max() < 1e-6


def test_coulomb_friction_stronger_than_the_push_keeps_the_joint_stuck() -> None:
    n = model().dof
    push = np.zeros(n)
    push[0] = 2.0  # the base joint carries no gravity: only the push
    weak = arm(coulomb_nm=np.full(n, 5.0))
    strong_push = arm(coulomb_nm=np.full(n, 1.0))
    for a in (weak, strong_push):
        for _ in range(400):
            a.step(a.gravity_nm() + push, H)
    assert weak.dq[0] == 0.0 and weak.q[0] == model().home_rad[0]
    assert strong_push.dq[0] > 0.0


def test_holding_brakes_add_to_the_friction() -> None:
    a = arm()
    a.holding_nm[:] = 1000.0  # brakes that hold far more than gravity
    q0 = a.q.copy()
    run(a, 0.2)
    assert np.array_equal(a.q, q0) and not a.dq.any()


def test_hard_stops_hold_a_joint_at_its_limit() -> None:
    a = arm(hard_stops=True)
    push = np.zeros(a.dof)
    push[0] = 50.0
    run(a, 3.0, push)
    assert a.q[0] == a.q_hi[0]
    assert a.dq[0] == 0.0  # no velocity into the stop
    b = arm()  # without hard stops the joint goes past the URDF's limit
    run(b, 3.0, push)
    assert b.q[0] > b.q_hi[0]


def test_armature_makes_the_joint_slower_to_accelerate() -> None:
    n = model().dof
    push = np.zeros(n)
    push[0] = 5.0
    bare, geared = arm(), arm(armature_kg_m2=np.full(n, 2.0))
    for a in (bare, geared):
        for _ in range(100):
            a.step(a.gravity_nm() + push, H)
    assert 0.0 < geared.dq[0] < 0.8 * bare.dq[0]
