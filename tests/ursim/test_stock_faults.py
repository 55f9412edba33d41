"""Faults injected into the simulated controller (its control channel), seen through stock
ur_rtde's RTDEReceiveInterface and DashboardClient; the controller boots powered off, as a real
one does. No RTDEControlInterface here: after a dropped RTDE connection its reconnection loop
does not end (`should_reconnect` is never reset in `receiveCallback`, ur_rtde 1.5.8's source),
and with the installed 1.6.5 the client process died of SIGSEGV within seconds."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from orccadd.ursim.process import UrSimProcess
from tests.ursim.conftest import STOCK_TIMEOUT, UR5E_RTDE, distinct_timestamps, wait_until

dashboard_client = pytest.importorskip("dashboard_client")
rtde_receive = pytest.importorskip("rtde_receive")

pytestmark = STOCK_TIMEOUT
HOST = "127.0.0.1"


@pytest.fixture(scope="module")
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(UR5E_RTDE) as s:
        yield s


@pytest.fixture
def receive(sim: UrSimProcess) -> Iterator[Any]:
    r = rtde_receive.RTDEReceiveInterface(HOST)
    yield r
    if r.isConnected():
        r.disconnect()


@pytest.fixture
def dashboard(sim: UrSimProcess) -> Iterator[Any]:
    d = dashboard_client.DashboardClient(HOST)
    d.connect()
    yield d
    d.disconnect()


def power_up(d: Any) -> None:
    d.powerOn()
    wait_until(lambda: d.robotmode() == "Robotmode: IDLE", 3.0, "IDLE")
    d.brakeRelease()
    wait_until(lambda: d.robotmode() == "Robotmode: RUNNING", 3.0, "RUNNING")


def test_boots_powered_off_then_powers_on_and_releases_the_brakes(receive: Any, dashboard: Any) -> None:
    assert dashboard.robotmode() == "Robotmode: POWER_OFF"
    assert receive.getRobotMode() == 3 and receive.getRobotStatus() & 1 == 0  # not powered
    assert receive.getJointMode() == [239] * 6  # JOINT_POWER_OFF_MODE
    power_up(dashboard)
    wait_until(lambda: receive.getRobotMode() == 7, 2.0, "RUNNING over RTDE")
    assert receive.getRobotStatus() & 1 and receive.getJointMode() == [253] * 6  # JOINT_RUNNING_MODE


def test_emergency_stop_powers_off_until_released(sim: UrSimProcess, receive: Any, dashboard: Any) -> None:
    if dashboard.robotmode() != "Robotmode: RUNNING":
        power_up(dashboard)
    sim.inject("emergency_stop")
    wait_until(receive.isEmergencyStopped, 2.0, "the emergency stop")
    assert receive.getSafetyMode() == 7  # ROBOT_EMERGENCY_STOP
    wait_until(lambda: receive.getRobotMode() == 3, 2.0, "power off")
    dashboard.powerOn()
    time.sleep(0.5)
    assert dashboard.robotmode() == "Robotmode: POWER_OFF"  # not while the stop is engaged
    sim.inject("emergency_stop_release")
    wait_until(lambda: receive.getSafetyMode() == 1, 2.0, "NORMAL")
    power_up(dashboard)


def test_a_stalled_stream_freezes_then_resumes(sim: UrSimProcess, receive: Any) -> None:
    sim.inject("stream_stall", duration_s=1.5)  # ur_rtde gives up after 2.5 s without data
    time.sleep(0.1)
    frozen = receive.getTimestamp()
    time.sleep(0.3)
    assert receive.getTimestamp() == frozen
    time.sleep(1.3)
    assert receive.isConnected()
    stamps = distinct_timestamps(receive, 0.3)
    assert len(stamps) > 20 and stamps[0] > frozen + 0.3  # the newest data, not a backlog


def test_a_dropped_connection_is_seen_and_reconnects(sim: UrSimProcess, receive: Any, dashboard: Any) -> None:
    sim.inject("drop_connection", ports="all")
    wait_until(lambda: not receive.isConnected(), 2.0, "the RTDE client noticing")
    with pytest.raises(RuntimeError):
        dashboard.robotmode()
    assert receive.reconnect()
    stamps = distinct_timestamps(receive, 0.3)
    assert len(stamps) > 20
    dashboard.connect()
    assert dashboard.robotmode() == "Robotmode: RUNNING"  # the controller itself carried on


def test_a_controller_restart_closes_the_ports_and_boots_again(sim: UrSimProcess, receive: Any) -> None:
    wait_until(lambda: receive.getTimestamp() > 2.0, 5.0, "the controller up for 2 s")
    injected = time.monotonic()
    sim.inject("controller_restart", down_s=1.0)
    wait_until(lambda: not receive.isConnected(), 2.0, "the RTDE client noticing")
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((HOST, 30004), timeout=2).close()
    wait_until(lambda: not sim.status()["down"], 5.0, "the controller back")
    assert receive.reconnect()
    assert receive.getRobotMode() == 3  # booted powered off again
    assert receive.getTimestamp() < time.monotonic() - injected  # its clock started again
    d = dashboard_client.DashboardClient(HOST)
    d.connect()
    assert d.robotmode() == "Robotmode: POWER_OFF"
    d.disconnect()
    assert np.isfinite(receive.getActualQ()).all()
