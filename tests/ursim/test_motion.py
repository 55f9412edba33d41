"""The controller's trajectory generation: movej, speedj, stopj and servoj, on simulated time."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from orccadd.ursim.arm import rotation_vector
from orccadd.ursim.motion import MoveJ, ServoJ, SpeedJ, StopJ, Target

H = 0.002
V_MAX = np.full(6, 3.14)
A_MAX = np.array([6.0, 6.0, 6.0, 10.0, 10.0, 10.0])


def run(motion: MoveJ | StopJ | SpeedJ | ServoJ, tgt: Target, seconds: float, h: float = H) -> list[Target]:
    """The target after each cycle (copies), until `seconds` or the motion ends."""
    out = []
    for _ in range(round(seconds / h)):
        done = motion.step(tgt, h)
        snap = Target(6)
        snap.q[:], snap.qd[:], snap.qdd[:] = tgt.q, tgt.qd, tgt.qdd
        out.append(snap)
        if done:
            break
    return out


def test_movej_arrives_with_every_joint_together_within_the_limits() -> None:
    tgt = Target(6)
    goal = np.array([1.0, -0.5, 0.25, 0.0, 0.0, 2.0])
    trace = run(MoveJ(goal, 1.0, 1.4, V_MAX, A_MAX), tgt, 10.0)
    assert np.allclose(tgt.q, goal) and not tgt.qd.any()
    qd = np.array([t.qd for t in trace])
    qdd = np.array([t.qdd for t in trace])
    assert np.abs(qd).max(axis=0)[5] == pytest.approx(1.0, rel=1e-6)  # the leading axis cruises at v
    assert (np.abs(qdd) <= 1.4 + 1e-9).all()
    # all joints on one straight line in joint space: each joint's share of the way is the same
    moving = [0, 1, 2, 5]
    shares = np.array([t.q for t in trace])[:, moving] / goal[moving]
    assert np.allclose(shares, shares[:, :1])
    # trapezoid: 2 rad at v = 1, a = 1.4 takes 2/1 + 1/1.4 s
    assert len(trace) * H == pytest.approx(2.0 + 1.0 / 1.4, abs=2 * H)


def test_movej_lowers_the_leading_speed_and_acceleration_to_every_joints_limit() -> None:
    tgt = Target(6)
    goal = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    goal[0], goal[3] = 0.5, 1.0  # joint 3 leads; joint 0 would be fine too
    v_max = V_MAX.copy()
    v_max[3] = 0.5
    trace = run(MoveJ(goal, 3.0, 40.0, v_max, A_MAX), tgt, 10.0)
    qd = np.abs(np.array([t.qd for t in trace]))
    qdd = np.abs(np.array([t.qdd for t in trace]))
    assert qd[:, 3].max() == pytest.approx(0.5, rel=1e-6)
    assert (qdd <= A_MAX + 1e-9).all()
    assert np.allclose(tgt.q, goal)


def test_stopj_brings_every_joint_to_rest_together() -> None:
    tgt = Target(6)
    tgt.qd[:] = [1.0, -0.5, 0.0, 0.2, 0.0, 0.0]
    trace = run(StopJ(2.0, A_MAX), tgt, 5.0)
    assert not tgt.qd.any()
    assert len(trace) * H == pytest.approx(0.5, abs=2 * H)  # 1 rad/s at 2 rad/s²
    assert tgt.q[0] == pytest.approx(0.25, abs=1e-3)  # v²/2a
    assert tgt.q[1] == pytest.approx(-0.125, abs=1e-3)


def test_speedj_ramps_at_the_leading_acceleration_and_holds_the_speed() -> None:
    tgt = Target(6)
    speed = SpeedJ(A_MAX)
    speed.set(np.array([0.0, 0.4, 0.0, 0.0, 0.0, -0.2]), 0.8)
    run(speed, tgt, 0.25)
    assert tgt.qd[1] == pytest.approx(0.2, abs=1e-9)  # 0.8 rad/s² for 0.25 s
    assert tgt.qd[5] == pytest.approx(-0.1, abs=1e-9)
    run(speed, tgt, 1.0)
    assert tgt.qd[1] == pytest.approx(0.4) and not tgt.qdd.any()


@pytest.mark.parametrize("h", [0.002, 0.008])  # e-Series, CB3
def test_servoj_follows_a_ramp_lookahead_seconds_late(h: float) -> None:
    tgt = Target(6)
    servo = ServoJ(6)
    lookahead, v = 0.1, 0.2
    for k in range(round(3.0 / h)):
        q_ref = np.zeros(6)
        q_ref[2] = v * k * h
        servo.set(q_ref, lookahead, 300.0)
        servo.step(tgt, h)
    assert tgt.qd[2] == pytest.approx(v, rel=1e-3)
    assert q_ref[2] - tgt.q[2] == pytest.approx(v * lookahead, rel=0.05)


def test_servoj_is_stable_at_its_stiffest_on_a_cb3_cycle() -> None:
    tgt = Target(6)
    servo = ServoJ(6)
    servo.set(np.full(6, 0.01), 0.03, 2000.0)
    run(servo, tgt, 2.0, h=0.008)
    assert np.allclose(tgt.q, 0.01, atol=1e-6)


def test_rotation_vectors_match_pinocchio_including_near_half_turns() -> None:
    rng = np.random.default_rng(7)
    for k in range(2000):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = np.pi - 1e-9 * k if k % 2 else rng.uniform(0.0, np.pi)
        r = pin.exp3(axis * angle)
        assert np.allclose(pin.exp3(np.array(rotation_vector(r))), r, atol=1e-7)
    assert rotation_vector(np.eye(3)) == (0.0, 0.0, 0.0)
