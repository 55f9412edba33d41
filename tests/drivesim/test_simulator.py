"""Simulated CiA 402 drives driven by canopen's own BaseNode402 (a client nobody here wrote)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import can
import canopen
import pytest

from orccadd.config import load_robot_config, with_backend
from orccadd.drivesim.axis import AxisUnits
from orccadd.drivesim.simulator import AxisSpec, DriveSimulator
from tests.conftest import UR5E, eds

UNITS = AxisUnits(counts_per_rev=4096, gear_ratio=100.0, rated_torque_nm=0.5)


class Rig:
    def __init__(self, eds_file: str) -> None:
        channel = f"drivesim-{id(self)}"
        cfg = with_backend(load_robot_config(UR5E), "sim")
        self.sim_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        specs = [AxisSpec(j + 1, eds_file, UNITS) for j in range(cfg.dof)]
        self.sim = DriveSimulator(cfg, specs, self.sim_bus)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.sim.run, args=(self.stop.is_set,), daemon=True)
        self.network = canopen.Network()
        self.network.connect(interface="virtual", channel=channel, receive_own_messages=False)
        self.thread.start()

    def close(self) -> None:
        self.network.sync.stop()
        self.stop.set()
        self.thread.join()
        self.network.disconnect()
        self.sim_bus.shutdown()


@pytest.fixture(params=["ros_canopen/Elmo.dcf", "canopen/e35.eds"])
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(str(eds(request.param)))
    try:
        yield r
    finally:
        r.close()


def test_basenode402_enables_and_moves_a_drive_in_csp(rig: Rig) -> None:
    node = canopen.BaseNode402(1, rig.sim.nodes[0].eds)
    rig.network.add_node(node)
    node.nmt.state = "PRE-OPERATIONAL"
    node.tpdo.read()
    node.rpdo.read()
    node.tpdo[1].clear()
    node.tpdo[1].add_variable(0x6041)
    node.tpdo[1].add_variable(0x6064)
    node.tpdo[1].trans_type = 1
    node.tpdo[1].enabled = True
    node.rpdo[1].clear()
    node.rpdo[1].add_variable(0x6040)
    node.rpdo[1].add_variable(0x607A)
    node.rpdo[1].trans_type = 1
    node.rpdo[1].enabled = True
    for pdos in (node.tpdo, node.rpdo):
        for k in range(2, 5):
            if k in pdos.map:
                pdos[k].enabled = False
        pdos.save()
    node.setup_402_state_machine(read_pdos=False)
    node.sdo[0x6060].raw = 8  # CSP
    rig.network.sync.start(0.004)
    node.nmt.state = "OPERATIONAL"
    node.rpdo[1][0x6040].raw = 0
    q0 = rig.sim.arm.q[0]
    node.rpdo[1][0x607A].raw = round(q0 * UNITS.counts_per_rad)
    node.rpdo[1].start(0.004)
    node.tpdo[1].wait_for_reception(2.0)
    node.state = "OPERATION ENABLED"
    assert node.state == "OPERATION ENABLED"
    assert node.op_mode == "CYCLIC SYNCHRONOUS POSITION"
    # ramp joint 0 by 0.2 rad over 1 s, one target per SYNC, as a controller would
    steps = 250
    for k in range(1, steps + 1):
        node.rpdo[1][0x607A].raw = round((q0 + 0.2 * k / steps) * UNITS.counts_per_rad)
        time.sleep(0.004)
    time.sleep(0.5)
    actual = node.tpdo[1][0x6064].raw / UNITS.counts_per_rad
    assert abs(actual - (q0 + 0.2)) < 0.01, (actual, q0)
    assert abs(rig.sim.arm.q[0] - (q0 + 0.2)) < 0.01
    # quick stop, then the drive is off (option 2: switch on disabled once stopped)
    node.controlword = 0x02  # quick stop
    deadline = time.monotonic() + 3
    while node.state != "SWITCH ON DISABLED" and time.monotonic() < deadline:
        time.sleep(0.02)
    assert node.state == "SWITCH ON DISABLED"
