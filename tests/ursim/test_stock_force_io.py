"""Stock ur_rtde (RTDEControlInterface, RTDEReceiveInterface, RTDEIOInterface) against the
simulated controller as its own process: force mode against a wall the test places, the F/T
sensor and its zeroing, tool contact, freedrive under a push, digital I/O, the speed slider,
payload and TCP offset."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from orccadd.ursim.process import UrSimProcess
from tests.ursim.conftest import STOCK_TIMEOUT, UR5E_RTDE, wait_until

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")
rtde_io = pytest.importorskip("rtde_io")

pytestmark = STOCK_TIMEOUT
HOST = "127.0.0.1"
Z_COMPLIANT = [0, 0, 1, 0, 0, 0]
LIMITS = [0.1] * 6


@pytest.fixture(scope="module")
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(UR5E_RTDE, "--boot", "running") as s:
        yield s


@pytest.fixture(scope="module")
def control(sim: UrSimProcess) -> Iterator[Any]:
    c = rtde_control.RTDEControlInterface(HOST)
    yield c
    c.disconnect()


@pytest.fixture(scope="module")
def receive(sim: UrSimProcess) -> Iterator[Any]:
    r = rtde_receive.RTDEReceiveInterface(HOST)
    yield r
    r.disconnect()


@pytest.fixture(scope="module")
def io(sim: UrSimProcess) -> Iterator[Any]:
    i = rtde_io.RTDEIOInterface(HOST)
    yield i
    i.disconnect()  # before the simulator stops: a connected RTDEIOInterface aborts the process


@pytest.fixture
def ready(sim: UrSimProcess, control: Any, receive: Any) -> Iterator[Any]:
    """The control script running; afterwards the world emptied and the arm back home."""
    if not control.isProgramRunning():
        assert control.reuploadScript()
    wait_until(control.isProgramRunning, what="the control script running")
    q0 = receive.getActualQ()
    yield control
    sim.inject("wall_remove")
    if not control.isProgramRunning():
        assert control.reuploadScript()
        wait_until(control.isProgramRunning, what="the control script running")
    assert control.moveJ(q0, 1.0, 2.0)


def force_z(receive: Any) -> float:
    return float(receive.getActualTCPForce()[2])


def test_force_mode_presses_on_a_wall_and_the_sensor_zeroes(
    sim: UrSimProcess, ready: Any, receive: Any
) -> None:
    z0 = receive.getActualTCPPose()[2]
    sim.inject("wall", point_m=[0.0, 0.0, z0 - 0.02], normal=[0.0, 0.0, 1.0], stiffness_n_m=5000)
    assert receive.getActualTCPForce() == pytest.approx([0.0] * 6, abs=1e-6)
    assert ready.zeroFtSensor()
    assert ready.forceMode([0.0] * 6, Z_COMPLIANT, [0, 0, -10, 0, 0, 0], 2, LIMITS)
    wait_until(lambda: receive.getActualTCPSpeed()[2] < -0.09, 2.0, "moving down at the speed limit")
    assert ready.toolContact([0, 0, -1, 0, 0, 0]) == 0  # not yet
    wait_until(lambda: abs(force_z(receive) - 10.0) < 0.3, 3.0, "10 N on the wall")
    time.sleep(0.1)
    assert ready.toolContact([0, 0, -1, 0, 0, 0]) > 0  # cycles since the contact began
    assert receive.getActualTCPPose()[2] == pytest.approx(z0 - 0.022, abs=1e-3)  # 2 mm into 5 kN/m
    assert ready.forceModeStop()
    assert ready.zeroFtSensor()  # pressed on the wall: the new zero
    wait_until(lambda: abs(force_z(receive)) < 0.3, 1.0, "zeroed")
    sim.inject("wall_remove")
    wait_until(lambda: abs(force_z(receive) + 10.0) < 0.5, 1.0, "the change since zeroing")
    assert ready.zeroFtSensor()


def test_a_wrench_above_the_tool_force_limit_stops_the_program(ready: Any, receive: Any) -> None:
    # real-time commands return once sent (ur_rtde does not wait for them): the refusal is the
    # program's runtime error, and every call after it returns false
    ready.forceMode([0.0] * 6, Z_COMPLIANT, [0, 0, -400, 0, 0, 0], 2, LIMITS)
    wait_until(lambda: not ready.isProgramRunning(), 2.0, "the runtime error")
    assert not ready.forceMode([0.0] * 6, Z_COMPLIANT, [0, 0, -10, 0, 0, 0], 2, LIMITS)
    assert receive.getRuntimeState() == 1  # STOPPED
    assert ready.reuploadScript()
    wait_until(ready.isProgramRunning, what="the control script running again")
    assert not ready.forceModeSetDamping(1.5)  # outside [0, 1]: refused, the program stops


def test_freedrive_follows_a_push_and_holds_still_without(
    sim: UrSimProcess, ready: Any, receive: Any
) -> None:
    p0 = np.array(receive.getActualTCPPose())
    assert ready.freedriveMode([1, 1, 0, 0, 0, 0], [0.0] * 6)  # x, y free in the base frame
    time.sleep(0.3)
    assert np.array(receive.getActualTCPPose())[0:3] == pytest.approx(p0[0:3], abs=2e-4)
    assert ready.getFreedriveStatus() == 0
    sim.inject("push", force_n=[0.0, 15.0, 15.0], duration_s=0.3)
    wait_until(lambda: receive.getActualTCPPose()[1] > p0[1] + 0.03, 2.0, "moved along y")
    wait_until(lambda: max(map(abs, receive.getActualTCPSpeed())) < 1e-3, 2.0, "still again")
    assert receive.getActualTCPPose()[2] == pytest.approx(p0[2], abs=2e-3)  # z is not free
    assert ready.endFreedriveMode()


def test_digital_outputs_and_inputs(sim: UrSimProcess, ready: Any, receive: Any, io: Any) -> None:
    assert io.setStandardDigitalOut(3, True) and io.setToolDigitalOut(1, True)
    wait_until(lambda: receive.getActualDigitalOutputBits() == (1 << 3) | (1 << 17), 1.0, "outputs 3, T1")
    assert receive.getDigitalOutState(3) and not receive.getDigitalOutState(2)
    assert io.setStandardDigitalOut(3, False) and io.setToolDigitalOut(1, False)
    wait_until(lambda: receive.getActualDigitalOutputBits() == 0, 1.0, "outputs cleared")
    sim.inject("digital_input", index=5, value=True)
    sim.inject("tool_digital_input", index=0, value=True)
    wait_until(lambda: receive.getActualDigitalInputBits() == (1 << 5) | (1 << 16), 1.0, "inputs 5, T0")
    assert receive.getDigitalInState(5) and not receive.getDigitalInState(4)
    sim.inject("digital_input", index=5, value=False)
    sim.inject("tool_digital_input", index=0, value=False)
    with pytest.raises(RuntimeError, match="index"):
        sim.inject("tool_digital_input", index=2, value=True)


def test_the_speed_slider_scales_speedj(ready: Any, receive: Any, io: Any) -> None:
    assert io.setSpeedSlider(0.5)
    wait_until(lambda: receive.getSpeedScaling() == pytest.approx(0.5), 2.0, "speed scaling 0.5")
    assert receive.getTargetSpeedFraction() == pytest.approx(0.5)
    assert ready.speedJ([0.0, 0.0, 0.0, 0.0, 0.0, 0.4], 2.0, 0.0)
    wait_until(lambda: abs(receive.getActualQd()[5] - 0.2) < 0.01, 3.0, "0.2 rad/s: half of 0.4")
    assert ready.speedStop(5.0)
    assert io.setSpeedSlider(1.0)
    wait_until(lambda: receive.getSpeedScaling() == pytest.approx(1.0), 2.0, "speed scaling 1")


def test_payload_and_tcp_offset(ready: Any, receive: Any) -> None:
    moment0 = np.array(receive.getTargetMoment())
    pose0 = np.array(receive.getActualTCPPose())
    assert ready.setPayload(3.0, [0.0, 0.0, 0.05])
    wait_until(lambda: receive.getPayload() == 3.0, 1.0, "payload 3 kg")
    time.sleep(0.2)
    lever_m = abs(pose0[0])  # the flange's reach from the shoulder lift's axis at home
    added = abs(receive.getTargetMoment()[1] - moment0[1])
    assert added == pytest.approx(3.0 * 9.81 * lever_m, rel=0.05)
    assert not ready.setPayload(8.0, [0.0, 0.0, 0.05])  # above the UR5e's 5 kg: runtime error
    assert receive.getPayload() == 3.0
    assert ready.reuploadScript()
    wait_until(ready.isProgramRunning, what="the control script running again")
    assert ready.setPayload(0.0, [0.0, 0.0, 0.05])
    assert ready.setTcp([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])  # at home the flange points down
    wait_until(lambda: abs(receive.getActualTCPPose()[2] - (pose0[2] - 0.1)) < 1e-4, 1.0, "TCP 10 cm lower")
    assert ready.setTcp([0.0] * 6)
