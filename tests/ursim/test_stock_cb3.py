"""Stock ur_rtde against the simulator as a CB3 controller (3.15, 125 Hz)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from orccadd.ursim.process import UrSimProcess
from tests.ursim.conftest import STOCK_TIMEOUT, UR5E_RTDE, distinct_timestamps, wait_until

dashboard_client = pytest.importorskip("dashboard_client")
rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")

pytestmark = STOCK_TIMEOUT
HOST = "127.0.0.1"


@pytest.fixture(scope="module")
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(UR5E_RTDE, "--cb3", "--boot", "running") as s:
        yield s


def test_a_cb3_streams_at_125_hz_and_runs_the_control_script(sim: UrSimProcess) -> None:
    d = dashboard_client.DashboardClient(HOST)
    d.connect()
    assert d.polyscopeVersion() == "3.15.7.106331"
    d.disconnect()
    r = rtde_receive.RTDEReceiveInterface(HOST)  # asks for 125 Hz from a 3.x controller
    c = rtde_control.RTDEControlInterface(HOST)
    try:
        stamps = distinct_timestamps(r, 1.0)
        assert 40 < len(stamps) < 250
        assert min(np.diff(stamps)) == pytest.approx(0.008, abs=1e-6)
        goal = np.array(r.getActualQ()) + np.array([0.0, 0.0, -0.2, 0.0, 0.0, 0.0])
        assert c.moveJ(goal.tolist(), 1.0, 2.0)
        wait_until(lambda: np.allclose(r.getActualQ(), goal, atol=2e-3), 2.0, "the goal")
    finally:
        c.disconnect()
        r.disconnect()
