"""The canopen402 resource against simulated CiA 402 drives in another process, over a bus in a
third (the userspace hub here; vcan0 where the kernel has it)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from orccadd.drivers.canopen.cia402 import State
from orccadd.physres.canopen402 import Canopen402Arm
from orccadd.robot import create_resource, load_robot_config
from orccadd.types import CommandMode, Status
from tests.canopen_rig import Rig, canopen_rig


@pytest.fixture(params=["ros_canopen/Elmo.dcf", "canopen/e35.eds"], ids=["elmo", "e35"])
def rig(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Rig]:
    with canopen_rig(tmp_path, request.param) as r:
        yield r


@pytest.fixture
def arm(rig: Rig) -> Iterator[Canopen402Arm]:
    res = create_resource(load_robot_config(rig.config))
    assert isinstance(res, Canopen402Arm)
    try:
        res.configure()
        res.activate(CommandMode.POSITION)
        yield res
    finally:
        if res.lifecycle.name != "FINALIZED":
            res.shutdown()


def run(arm: Canopen402Arm, seconds: float, command: Callable[[float], np.ndarray] | None = None) -> int:
    """Tick the resource on the wall clock (missed periods skipped, like the executor): read, then
    the command or `keep_alive`; the OR of the status flags seen."""
    period = arm.config.control_period_s
    t0 = nxt = time.monotonic()
    seen = 0
    while nxt - t0 < seconds:
        st = arm.read(nxt)
        seen |= st.status
        if command is not None:
            seen |= arm.write(nxt, command(nxt - t0))
        else:
            arm.keep_alive(nxt)
        nxt += period
        while nxt < time.monotonic():
            nxt += period
        time.sleep(max(0.0, nxt - time.monotonic()))
    return seen


def wait_for(arm: Canopen402Arm, flag: int, timeout_s: float) -> float:
    """Seconds until a read shows `flag` (AssertionError after `timeout_s`)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        now = time.monotonic()
        status = arm.read(now).status
        arm.keep_alive(now)  # one tick: read, then a command or this
        if status & flag:
            return time.monotonic() - t0
        time.sleep(arm.config.control_period_s)
    raise AssertionError(f"no {Status(flag)!r} within {timeout_s} s: {arm.fault_message}")


def test_startup_enables_every_axis_and_csp_moves_the_arm(rig: Rig, arm: Canopen402Arm) -> None:
    assert all(a.state is State.OPERATION_ENABLED for a in arm.master.axes)
    assert CommandMode.POSITION in arm.supported_modes
    q0 = arm.state.q_rad.copy()
    goal = q0 + np.array([0.3, -0.2, 0.2, 0.0, 0.1, -0.1])

    def ramp(t: float) -> np.ndarray:
        return q0 + (goal - q0) * min(1.0, t / 1.5)

    flags = run(arm, 2.5, ramp)
    assert not flags & (Status.FAULT | Status.COMM_LOST | Status.LIMIT_VIOLATION), arm.fault_message
    np.testing.assert_allclose(arm.state.q_rad, goal, atol=0.01)
    np.testing.assert_allclose(rig.drives.status()["q_rad"], goal, atol=0.01)  # the drives agree
    arm.safe_stop()
    wait_for(arm, Status.STOPPED, 5.0)
    assert all(a.state is State.SWITCH_ON_DISABLED for a in arm.master.axes)


@pytest.mark.parametrize("rig", ["ros_canopen/Elmo.dcf"], indirect=True)
def test_drive_fault_emcy_then_fault_reset_and_a_new_motion(rig: Rig, arm: Canopen402Arm) -> None:
    run(arm, 0.2, lambda t: arm.state.q_rad.copy())
    rig.drives.inject(3, "overcurrent")
    wait_for(arm, Status.FAULT, 2.0)
    assert arm.state.fault_code == 0x2310 and "node 3 (elbow_joint)" in arm.fault_message
    assert "over-current" in arm.fault_message
    arm.safe_stop()  # what the task does on a type 3: quick stop on every axis
    wait_for(arm, Status.STOPPED, 5.0)
    assert rig.drives.status()["states"][2] == "FAULT"
    arm.reset_fault()
    run(arm, 0.3)
    assert not arm.read(time.monotonic()).status & Status.FAULT
    arm.clear_stop()
    assert all(a.state is State.OPERATION_ENABLED for a in arm.master.axes)
    q0 = arm.state.q_rad.copy()
    flags = run(arm, 1.0, lambda t: q0 + np.array([0, 0, 0.1 * min(1.0, t / 0.5), 0, 0, 0]))
    assert not flags & (Status.FAULT | Status.COMM_LOST), arm.fault_message
    assert arm.state.q_rad[2] == pytest.approx(q0[2] + 0.1, abs=0.01)


@pytest.mark.parametrize("rig", ["ros_canopen/Elmo.dcf"], indirect=True)
def test_a_silent_heartbeat_is_comm_lost_within_three_periods(rig: Rig, arm: Canopen402Arm) -> None:
    heartbeat_ms = arm.settings.heartbeat_ms  # the rig's 250 ms, not the file's 100 ms
    timeout_s = 3 * heartbeat_ms / 1000  # the master's consumer timeout: 3 silent heartbeat periods
    assert not run(arm, 0.3) & Status.COMM_LOST, arm.fault_message  # every drive's heartbeat arrives
    rig.drives.inject(4, "heartbeat_silence")
    wait_for(arm, Status.COMM_LOST, 10 * timeout_s)  # reported within an order of magnitude of it
    now = time.monotonic()
    assert "node 4 (wrist_1_joint): heartbeat lost (" in arm.fault_message
    assert f"ms > 3 × {heartbeat_ms} ms)" in arm.fault_message
    silent_s = {a.node_id: now - a.heartbeat_s for a in arm.master.axes}
    assert silent_s[4] > timeout_s, silent_s  # not before the timeout
    # only node 4 went silent: the other drives' heartbeats were still arriving
    assert all(s < timeout_s for n, s in silent_s.items() if n != 4), silent_s


@pytest.mark.parametrize("rig", ["ros_canopen/Elmo.dcf"], indirect=True)
def test_a_node_silent_on_pdos_is_comm_lost(rig: Rig, arm: Canopen402Arm) -> None:
    run(arm, 0.3)
    rig.drives.inject(6, "node_silence")
    wait_for(arm, Status.COMM_LOST, 3.0)
    assert "node 6 (wrist_3_joint) silent: no TPDO" in arm.fault_message


@pytest.mark.parametrize("rig", ["ros_canopen/Elmo.dcf"], indirect=True)
def test_the_bus_dying_is_comm_lost_with_a_clear_message(rig: Rig, arm: Canopen402Arm) -> None:
    if rig.hub is None:
        pytest.skip("the kernel's vcan0 cannot be killed from a test")
    run(arm, 0.3)
    rig.hub.kill()
    wait_for(arm, Status.COMM_LOST, 3.0)
    assert "CAN bus can0 (socketcand 127.0.0.1:" in arm.fault_message
    arm.safe_stop()
    wait_for(arm, Status.STOPPED, 10.0)  # unreachable drives: presumed stopped by their watchdogs
