"""The Physical Resource contract, re-run by every backend (on the wall clock)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pinocchio as pin
import pytest

from orccadd.physres import PhysicalResource
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.types import CommandMode, Lifecycle, Status
from tests.conftest import UR5E

BACKENDS = ["sim", "sim_process"]


@pytest.fixture(params=BACKENDS)
def resource(request: pytest.FixtureRequest) -> Iterator[PhysicalResource]:
    res = create_resource(with_backend(load_robot_config(UR5E), request.param))
    res.configure()
    yield res
    if res.lifecycle is not Lifecycle.FINALIZED:
        res.shutdown()


def drive(res: PhysicalResource, seconds: float, extra_nm: float = 0.0) -> None:
    """Gravity compensation (+ a push) every period on the wall clock."""
    data = res.model.new_data()
    period = res.config.control_period_s
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        st = res.read(time.monotonic())
        res.write(time.monotonic(), pin.computeGeneralizedGravity(res.model.model, data, st.q_rad) + extra_nm)
        time.sleep(period)


def test_activate_reports_the_measured_position(resource: PhysicalResource) -> None:
    resource.activate(CommandMode.TORQUE)
    q0 = resource.state.q_rad.copy()
    assert np.abs(q0).max() > 0.1  # the configured initial pose, not zeros
    drive(resource, 0.2)
    assert np.abs(resource.state.q_rad - q0).max() < 0.01
    assert not resource.state.status & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION)


def test_torque_beyond_limit_is_clamped(resource: PhysicalResource) -> None:
    resource.activate(CommandMode.TORQUE)
    resource.read(time.monotonic())
    flags = resource.write(time.monotonic(), np.full(resource.dof, 1e4))
    assert flags & Status.CMD_CLAMPED and not flags & Status.LIMIT_VIOLATION
    resource.safe_stop()


def test_position_steps_within_the_speed_limit_pass_unchanged(resource: PhysicalResource) -> None:
    # 0.1 + (0.3 - 0.1) == 0.30000000000000004: a step that needs no clamping must not be
    # rebuilt from the last command (that flagged a limit violation on exact commands)
    resource.activate(CommandMode.POSITION)
    q = resource.read(time.monotonic()).q_rad.copy()
    for x in np.linspace(q[0], 0.0, 100):  # bring joint 0 to zero at an allowed speed
        q[0] = x
        assert not resource.write(time.monotonic(), q) & Status.LIMIT_VIOLATION
    for k in range(1, 200):  # hovering around zero, as a held joint does: there it rounds
        cmd = q.copy()
        cmd[0] = 1e-7 * k * (1.0 if k % 3 else -0.37)
        flags = resource.write(time.monotonic(), cmd)
        assert not flags & (Status.CMD_CLAMPED | Status.LIMIT_VIOLATION), (k, flags)
    fast = q + 1.0  # a jump no joint can make in one period
    flags = resource.write(time.monotonic(), fast)
    assert flags & Status.CMD_CLAMPED and flags & Status.LIMIT_VIOLATION
    resource.safe_stop()


def test_safe_stop_brings_the_arm_to_rest(resource: PhysicalResource) -> None:
    resource.activate(CommandMode.TORQUE)
    drive(resource, 0.3, extra_nm=3.0)
    assert np.abs(resource.state.dq_rad_s).max() > 0.2
    assert resource.config.safe_stop.category == 1  # sim-ur5e's: decelerate, then torque off
    resource.safe_stop()
    st = resource.read(time.monotonic())
    assert st.status & Status.STOPPING and not st.status & Status.TORQUE_OFF, Status(st.status)
    drive(resource, 2.0)
    st = resource.state
    stopped_torque_off = Status.STOPPED | Status.TORQUE_OFF
    assert st.status & stopped_torque_off == stopped_torque_off, Status(st.status)
    assert np.abs(st.dq_rad_s).max() < 0.01


def test_device_fault_is_reported(resource: PhysicalResource) -> None:
    resource.activate(CommandMode.TORQUE)
    drive(resource, 0.05)
    resource.inject_fault("device", "over-current")
    drive(resource, 0.05)
    assert resource.state.status & Status.FAULT


@pytest.mark.parametrize("mode", [CommandMode.TORQUE, CommandMode.POSITION])
def test_a_command_with_nan_or_inf_is_not_sent(resource: PhysicalResource, mode: CommandMode) -> None:
    resource.activate(mode)
    st = resource.read(time.monotonic())
    good = np.zeros(resource.dof) if mode is CommandMode.TORQUE else st.q_rad.copy()
    for bad_value in (np.nan, np.inf, -np.inf):
        bad = good.copy()
        bad[2] = bad_value
        flags = resource.write(time.monotonic(), bad)
        assert flags & Status.LIMIT_VIOLATION, (bad_value, flags)  # a type 3 exception for the task
    assert resource.rejected_count == 3
    assert "NaN or an infinity" in resource.fault_message
    drive(resource, 0.05)  # the device never saw them: the arm's state stays finite
    assert np.isfinite(resource.state.vector).all()
    resource.safe_stop()
