"""Stock ur_rtde (RTDEReceiveInterface, RTDEControlInterface, DashboardClient) against the
simulated controller as its own process, on UR's fixed ports."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from orccadd.ursim.process import UrSimProcess
from tests.ursim.conftest import STOCK_TIMEOUT, UR5E_RTDE, distinct_timestamps, wait_until

dashboard_client = pytest.importorskip("dashboard_client")
rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")

pytestmark = STOCK_TIMEOUT
HOST = "127.0.0.1"
UNLOCK_DELAY_S = 1.0


@pytest.fixture(scope="module")
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(UR5E_RTDE, "--boot", "running", "--unlock-delay-s", str(UNLOCK_DELAY_S)) as s:
        yield s


@pytest.fixture(scope="module")
def control(sim: UrSimProcess) -> Iterator[Any]:
    c = rtde_control.RTDEControlInterface(HOST)
    yield c
    c.disconnect()  # before the simulator goes: a client left connected would try to reconnect


@pytest.fixture
def receive(sim: UrSimProcess) -> Iterator[Any]:
    r = rtde_receive.RTDEReceiveInterface(HOST)
    yield r
    r.disconnect()


@pytest.fixture
def dashboard(sim: UrSimProcess) -> Iterator[Any]:
    d = dashboard_client.DashboardClient(HOST)
    d.connect()
    yield d
    d.disconnect()


@pytest.fixture
def ready(control: Any, receive: Any) -> Any:
    """The control script running and the arm at rest (a test before may have stopped it)."""
    if not control.isProgramRunning():
        assert control.reuploadScript()
        wait_until(control.isProgramRunning, what="the control script running")
    return control


def test_receive_streams_at_the_controller_rate(sim: UrSimProcess, receive: Any) -> None:
    stamps = distinct_timestamps(receive, 1.0)
    # an order of magnitude only (a shared, loaded machine): hundreds of packages a second...
    assert 100 < len(stamps) < 1000
    # ...and among them consecutive ones, one 2 ms cycle apart on the controller's clock
    assert min(np.diff(stamps)) == pytest.approx(0.002, abs=1e-6)
    assert receive.getRobotMode() == 7 and receive.getSafetyMode() == 1  # RUNNING, NORMAL
    assert np.allclose(receive.getActualQ(), [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], atol=1e-3)
    assert receive.getActualTCPPose()[2] > 0.0  # the flange above the base at home


def test_movej_reaches_its_target(ready: Any, receive: Any) -> None:
    q0 = np.array(receive.getActualQ())
    goal = q0 + np.array([0.3, -0.2, 0.2, 0.0, 0.1, -0.3])
    assert ready.moveJ(goal.tolist(), 1.0, 2.0)  # blocks until done
    wait_until(lambda: np.allclose(receive.getActualQ(), goal, atol=1e-3), 2.0, "the goal")
    assert np.allclose(receive.getTargetQ(), goal, atol=1e-9)
    assert ready.moveJ(q0.tolist(), 1.0, 2.0)


def test_a_servoj_stream_is_followed_to_its_last_target(ready: Any, receive: Any) -> None:
    q0 = np.array(receive.getActualQ())
    wrist = np.array([0, 0, 0, 0, 0.15, 0])
    steps = 500
    # 0.15 rad on wrist 2 in 1 s, one target per 2 ms; gain 150: a stall of this test process
    # of 0.2 s (a loaded machine) still asks the servo for less than the 10 rad/s² it may use
    for k in range(1, steps + 1):
        t = ready.initPeriod()
        assert ready.servoJ((q0 + wrist * k / steps).tolist(), 0.5, 0.5, 0.002, 0.1, 150)
        ready.waitPeriod(t)
    goal = q0 + wrist
    for _ in range(250):  # hold the last target while the servo catches up
        t = ready.initPeriod()
        ready.servoJ(goal.tolist(), 0.5, 0.5, 0.002, 0.1, 150)
        ready.waitPeriod(t)
    wait_until(lambda: np.allclose(receive.getActualQ(), goal, atol=2e-3), 3.0, "the servo's last target")
    assert ready.servoStop()
    assert receive.getSafetyMode() == 1
    assert ready.moveJ(q0.tolist(), 1.0, 2.0)


def test_speedj_runs_at_the_speed_until_speed_stop(ready: Any, receive: Any) -> None:
    assert ready.speedJ([0.0, 0.0, 0.0, 0.0, 0.0, 0.4], 2.0, 0.0)
    wait_until(lambda: abs(receive.getActualQd()[5] - 0.4) < 0.02, 3.0, "0.4 rad/s on wrist 3")
    assert ready.speedStop(5.0)
    wait_until(lambda: max(map(abs, receive.getActualQd())) < 0.01, 2.0, "rest")


def test_stopj_stops_an_asynchronous_movej_short_of_its_goal(ready: Any, receive: Any) -> None:
    q0 = np.array(receive.getActualQ())
    goal = q0 + np.array([2.5, 0, 0, 0, 0, 0])
    assert ready.moveJ(goal.tolist(), 1.0, 1.0, True)  # asynchronous: returns at once
    wait_until(lambda: receive.getActualQd()[0] > 0.5, 3.0, "moving")
    ready.stopJ(2.0)
    wait_until(lambda: max(map(abs, receive.getActualQd())) < 0.01, 3.0, "rest")
    assert receive.getActualQ()[0] < goal[0] - 0.2
    assert ready.moveJ(q0.tolist(), 1.0, 2.0)


def test_dashboard_power_cycle(ready: Any, receive: Any, dashboard: Any) -> None:
    assert dashboard.polyscopeVersion() == "5.26.0.0"
    assert dashboard.robotmode() == "Robotmode: RUNNING"
    assert dashboard.safetystatus() == "Safetystatus: NORMAL"
    assert dashboard.programState() == "PLAYING rtde_control"
    dashboard.powerOff()
    assert dashboard.robotmode() == "Robotmode: POWER_OFF"
    wait_until(lambda: receive.getRobotMode() == 3 and not ready.isProgramRunning(), 2.0, "power off")
    dashboard.powerOn()
    wait_until(lambda: dashboard.robotmode() == "Robotmode: IDLE", 3.0, "IDLE")
    dashboard.brakeRelease()
    wait_until(lambda: dashboard.robotmode() == "Robotmode: RUNNING", 3.0, "RUNNING")
    dashboard.closeSafetyPopup()
    assert ready.reuploadScript()
    wait_until(ready.isProgramRunning, what="the control script running again")


def test_protective_stop_refuses_commands_until_unlocked(
    sim: UrSimProcess, ready: Any, receive: Any, dashboard: Any
) -> None:
    q = np.array(receive.getActualQ())
    sim.inject("protective_stop")
    injected = time.monotonic()
    wait_until(receive.isProtectiveStopped, 2.0, "the protective stop")
    with pytest.raises(RuntimeError, match="Cannot unlock protective stop"):
        dashboard.unlockProtectiveStop()  # too early
    assert receive.getSafetyMode() == 3  # PROTECTIVE_STOP
    assert receive.getSafetyStatusBits() & (1 << 2)  # is protective stopped
    assert dashboard.safetystatus() == "Safetystatus: PROTECTIVE_STOP"
    assert not ready.moveJ((q + 0.1).tolist(), 1.0, 2.0)
    time.sleep(max(0.0, injected + UNLOCK_DELAY_S + 0.1 - time.monotonic()))
    assert not ready.moveJ((q + 0.1).tolist(), 1.0, 2.0)  # still stopped
    dashboard.unlockProtectiveStop()
    wait_until(lambda: receive.getSafetyMode() == 1, 2.0, "NORMAL")
    assert not ready.isProgramRunning()  # paused by the stop: the client uploads it again
    assert ready.reuploadScript()
    wait_until(ready.isProgramRunning, what="the control script running again")
    assert ready.moveJ(q.tolist(), 1.0, 2.0)


def test_a_second_simulator_refuses_taken_ports(sim: UrSimProcess) -> None:
    with pytest.raises(RuntimeError, match=r"127\.0\.0\.1:\d+ is already in use"):
        UrSimProcess(UR5E_RTDE, lock=False, timeout_s=30)
