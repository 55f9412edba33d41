"""The simulated arm: lifecycle, limit enforcement, stop categories, determinism, latency."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from orccadd.errors import LifecycleError, ResourceError
from orccadd.fault import FaultKind
from orccadd.physres.sim import SimulatedArm
from orccadd.robot import create_resource, load_robot_config
from orccadd.types import CommandMode, Lifecycle, Status
from tests.conftest import PANDA, UR5E

DT = 0.002


def make(path=UR5E, mode: CommandMode | None = CommandMode.TORQUE) -> SimulatedArm:  # type: ignore[no-untyped-def]
    res = create_resource(load_robot_config(path))
    assert isinstance(res, SimulatedArm)
    res.configure()
    if mode is not None:
        res.activate(mode)
    return res


def hold_gravity(res: SimulatedArm, ticks: int, t0: float = 0.0, extra: float = 0.0) -> None:
    data = res.model.new_data()
    for k in range(ticks):
        st = res.read(t0 + k * DT)
        res.write(t0 + k * DT, pin.computeGeneralizedGravity(res.model.model, data, st.q_rad) + extra)


def test_lifecycle_order_is_enforced() -> None:
    res = create_resource(load_robot_config(UR5E))
    with pytest.raises(LifecycleError, match="cannot activate while unconfigured"):
        res.activate(CommandMode.TORQUE)
    res.configure()
    with pytest.raises(LifecycleError, match="cannot configure while inactive"):
        res.configure()
    res.activate(CommandMode.POSITION)
    assert res.lifecycle is Lifecycle.ACTIVE
    res.deactivate()
    res.shutdown()
    assert res.lifecycle is Lifecycle.FINALIZED


def test_gravity_compensation_holds_the_arm() -> None:
    res = make()
    q0 = res.state.q_rad.copy() if res.state.t_s else res.q.copy()
    hold_gravity(res, 500)
    assert np.abs(res.state.q_rad - q0).max() < 1e-3


def test_without_torque_the_arm_falls_and_brakes_hold_it() -> None:
    res = make()
    model, data = res.model.model, res.model.new_data()
    pe0 = pin.computePotentialEnergy(model, data, res.state.q_rad)
    for k in range(200):
        res.read(k * DT)
        res.write(k * DT, np.zeros(res.dof))
    assert np.abs(res.state.dq_rad_s).max() > 0.1  # falling under gravity (friction is not enough)
    # downhill: it lost potential energy (25 J measured in these 0.4 s)
    fell_j = pe0 - pin.computePotentialEnergy(model, data, res.state.q_rad)
    assert fell_j > 5.0, fell_j
    res.deactivate()  # brakes
    for k in range(200, 600):
        res.read(k * DT)
    assert np.abs(res.state.dq_rad_s).max() == 0.0


def test_torque_is_saturated_without_type_3() -> None:
    res = make()
    flags = res.write(0.0, np.full(res.dof, 1000.0))
    assert flags & Status.CMD_CLAMPED and not flags & Status.LIMIT_VIOLATION
    np.testing.assert_allclose(res._cmd, res.model.tau_max_nm)


def test_position_command_beyond_limits_is_clamped_and_a_violation() -> None:
    res = make(mode=CommandMode.POSITION)
    res.read(0.0)
    cmd = res.state.q_rad.copy()
    cmd[2] = 10.0
    flags = res.write(0.0, cmd)
    assert flags & Status.CMD_CLAMPED and flags & Status.LIMIT_VIOLATION
    step = res.model.v_max_rad_s[2] * res.config.control_period_s * res.config.limits.velocity_tolerance
    assert res._cmd[2] == pytest.approx(res.state.q_rad[2] + step)


def test_measured_position_beyond_limit_is_flagged() -> None:
    res = make()
    res.q[2] = res.model.q_max_rad[2] + 0.1
    assert res.read(0.0).status & Status.LIMIT_VIOLATION
    hi = res.model.q_max_rad[2] + res.config.limits.position_tolerance_rad
    f = res.fault
    assert f is not None and (f.kind, f.joint) == (FaultKind.LIMIT, "elbow_joint"), f
    assert f.text.startswith(f"measured position of elbow_joint {res.q[2]:.4g} rad outside")
    assert f"{hi:.4g}]" in f.text, f  # the limit it crossed, with its tolerance


def test_unsupported_mode_is_refused_clearly() -> None:
    res = make(mode=None)
    res.supported_modes = frozenset({CommandMode.TORQUE})  # as a device's configure may narrow it
    with pytest.raises(ResourceError, match="cannot command position"):
        res.activate(CommandMode.POSITION)


STOPPED_TORQUE_OFF = Status.STOPPED | Status.TORQUE_OFF


@pytest.mark.parametrize("category", [0, 1, 2])
def test_safe_stop_categories(robot_variant, category: int) -> None:  # type: ignore[no-untyped-def]
    res = make(robot_variant(("category = 1", f"category = {category}")))
    hold_gravity(res, 150, extra=4.0)  # push: the arm moves
    t0, v0 = res.state.t_s, res.state.dq_rad_s.copy()
    assert np.abs(v0).max() > 0.3
    res.safe_stop()
    flags = res.write(t0 + DT, np.full(res.dof, 50.0))
    t = t0 + DT * np.arange(1, 1001)  # 2 s
    dq, status, tau, q, brakes, torque_on = [], [], [], [], [], []
    for k, tk in enumerate(t):
        st = res.read(tk)
        dq.append(np.abs(st.dq_rad_s))
        status.append(st.status)
        tau.append(st.tau_nm.copy())
        q.append(st.q_rad.copy())
        brakes.append(res.brakes_engaged)
        torque_on.append(res.torque_on)
        res.write(tk, np.full(res.dof, 50.0 if k % 2 else -50.0))  # must be ignored
    speed = np.array(dq)
    if category == 0:  # torque off and brakes at once, no controlled deceleration
        assert flags & STOPPED_TORQUE_OFF == STOPPED_TORQUE_OFF and not flags & Status.STOPPING
        assert all(s & STOPPED_TORQUE_OFF == STOPPED_TORQUE_OFF for s in status)
        assert all(brakes) and not any(torque_on)
        assert not np.array(tau).any()  # not one period of the commands
        assert speed[5:].max() == 0.0  # the brakes (2 × max torque) hold it: 4 periods measured
        return
    a = res.config.safe_stop.deceleration_rad_s2
    ramp = np.maximum(np.abs(v0) - a * (t - t0)[:, None], 0.0)
    t_ramp = float(np.abs(v0).max() / a)  # ~1.16 s here
    assert flags & Status.STOPPING and not flags & STOPPED_TORQUE_OFF
    # every joint follows the configured deceleration ramp (measured within 0.036 rad/s), the
    # commands ignored, with torque on and brakes off
    np.testing.assert_allclose(speed, ramp, rtol=0, atol=0.1)
    ramping = np.flatnonzero(t - t0 < t_ramp)
    assert all(status[k] & Status.STOPPING and not status[k] & STOPPED_TORQUE_OFF for k in ramping)
    assert not any(brakes[k] for k in ramping) and all(torque_on[k] for k in ramping)
    # then at rest, stopped as soon as the ramp ends
    first = next(k for k, s in enumerate(status) if s & Status.STOPPED)
    assert t_ramp <= t[first] - t0 < t_ramp + 0.05, (t[first] - t0, t_ramp)
    assert speed[first:].max() < 0.01
    if category == 1:  # torque off and brakes
        assert all(s & STOPPED_TORQUE_OFF == STOPPED_TORQUE_OFF for s in status[first:])
        assert all(brakes[first:]) and not any(torque_on[first:])
        assert not np.array(tau[first:]).any()
    else:  # holds the position with torque on, against gravity
        assert all(s & STOPPED_TORQUE_OFF == Status.STOPPED for s in status[first:])
        assert not any(brakes[first:]) and all(torque_on[first:])
        np.testing.assert_allclose(q[-1], q[first], rtol=0, atol=1e-6)
        gravity = pin.computeGeneralizedGravity(res.model.model, res.model.new_data(), q[-1])
        assert np.abs(gravity).max() > 10.0
        np.testing.assert_allclose(tau[-1], gravity, rtol=0, atol=1e-6)


def test_clear_stop_refused_while_faulted_then_allowed() -> None:
    res = make()
    res.inject_fault("device", "following error")
    res.read(0.0)
    res.safe_stop()
    with pytest.raises(ResourceError, match="following error"):
        res.clear_stop()
    res.reset_fault()
    res.read(DT)
    res.clear_stop()
    assert not res.stopping_or_stopped


def test_noise_is_deterministic_for_a_seed(robot_variant) -> None:  # type: ignore[no-untyped-def]
    noisy = ("seed = 1", "seed = 7\nnoise_q_rad = 0.001\nnoise_dq_rad_s = 0.01")
    runs = []
    for _ in range(2):
        res = make(robot_variant(noisy))
        hold_gravity(res, 100)
        runs.append(res.state.q_rad.copy())
    np.testing.assert_array_equal(runs[0], runs[1])
    other = make(robot_variant(("seed = 1", "seed = 8\nnoise_q_rad = 0.001")))
    hold_gravity(other, 100)
    assert not np.array_equal(runs[0], other.state.q_rad)


def test_latency_delays_measurements_by_whole_periods(robot_variant) -> None:  # type: ignore[no-untyped-def]
    res = make(robot_variant(("seed = 1", "seed = 1\nlatency_periods = 3")))
    seen, truth = [], []
    for k in range(40):
        st = res.read(k * DT)
        seen.append(st.q_rad[1])
        truth.append(res.q[1])
        res.write(k * DT, np.zeros(res.dof))  # falls: q changes every period
    assert seen[10:] == pytest.approx(truth[7:-3])


def test_panda_fingers_are_locked_out_of_the_model() -> None:
    res = make(PANDA)
    assert res.dof == 7 and res.model.model.nq == 7
