"""One simulated CiA 402 axis, driven through its node's SDO server (no bus, no thread)."""

from __future__ import annotations

import struct

import can
import pytest

from orccadd.drivers.canopen.cia402 import MODE_CSP, MODE_CST, State
from orccadd.drivesim.axis import NEVER, STRICT, Axis, AxisUnits, Strictness
from orccadd.drivesim.plant import DriveTrainArm
from orccadd.drivesim.slave import SlaveNode
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config, with_backend
from tests.conftest import UR5E, eds

UNITS = AxisUnits(counts_per_rev=4096, gear_ratio=100.0, rated_torque_nm=0.5)


def sdo_write(node: SlaveNode, index: int, sub: int, value: int, size: int, signed: bool = False) -> None:
    """An expedited SDO download, as a master sends it."""
    ccs = 0x23 | ((4 - size) << 2)
    body = value.to_bytes(size, "little", signed=signed).ljust(4, b"\0")
    data = struct.pack("<BHB", ccs, index, sub) + body
    node.on_frame(can.Message(arbitration_id=0x600 + node.node_id, data=data, is_extended_id=False), 0.0)


def enabled_in_csp(eds_file: str, strict: Strictness = STRICT) -> Axis:
    cfg = with_backend(load_robot_config(UR5E), "sim")
    arm = DriveTrainArm(cfg, RobotModel.from_config(cfg))
    arm.step_to(0.0)
    node = SlaveNode(1, str(eds(eds_file)), lambda msg: None)
    node.boot(0.0)
    axis = Axis(node, 0, arm, UNITS, strict)
    axis.boot()
    sdo_write(node, 0x6060, 0, MODE_CSP, 1)
    assert node.get(0x6061) == MODE_CSP  # shown (and run) from the write on
    for cw in (0x06, 0x07, 0x0F):  # transitions 2, 3, 4
        sdo_write(node, 0x6040, 0, cw, 2)
    assert axis.sm.state is State.OPERATION_ENABLED
    return axis


@pytest.fixture
def csp_axis() -> Axis:
    return enabled_in_csp("ros_canopen/Elmo.dcf")


def target(axis: Axis, q_rad: float) -> None:
    sdo_write(axis.node, 0x607A, 0, round(q_rad * UNITS.counts_per_rad), 4, signed=True)


def test_csp_velocity_feed_forward_uses_the_configured_interpolation_period(csp_axis: Axis) -> None:
    sdo_write(csp_axis.node, 0x60C2, 1, 2, 1)  # 2 × 10^-3 s
    sdo_write(csp_axis.node, 0x60C2, 2, -3, 1, signed=True)
    q0 = float(csp_axis.arm.q[0])
    target(csp_axis, q0)
    csp_axis.cycle(0.0, 0.002)
    target(csp_axis, q0 + 0.004)  # 4 mrad in one 2 ms cycle: 2 rad/s
    csp_axis.cycle(0.0001, 0.0001)  # a second SYNC 0.1 ms after the first (a delayed bus's burst)
    assert csp_axis.arm.velocity_ref[0] == pytest.approx(2.0, rel=1e-3)


def test_without_0x60c2_the_communication_cycle_period_counts() -> None:
    # a description without 0x60C2, whose 0x6502 (0x65) does not list csp: that check relaxed
    csp_axis = enabled_in_csp("ros_canopen/ISD860.eds", Strictness(supported_modes=False))
    assert not csp_axis.node.has(0x60C2, 1)
    sdo_write(csp_axis.node, 0x1006, 0, 4000, 4)  # 4 ms
    q0 = float(csp_axis.arm.q[0])
    target(csp_axis, q0)
    csp_axis.cycle(0.0, 0.004)
    target(csp_axis, q0 + 0.004)
    csp_axis.cycle(0.0001, 0.0001)
    assert csp_axis.arm.velocity_ref[0] == pytest.approx(1.0, rel=1e-3)


@pytest.mark.parametrize(("window", "faults"), [(100, True), (0xFFFFFFFF, False)])
def test_following_error_supervision(csp_axis: Axis, window: int, faults: bool) -> None:
    """0x6065 window (increments) held longer than 0x6066 (ms): EMCY 0x8611 and FAULT; the
    window 0xFFFFFFFF switches the supervision off (CiA 402)."""
    sdo_write(csp_axis.node, 0x6065, 0, window, 4)
    sdo_write(csp_axis.node, 0x6066, 0, 10, 2)
    target(csp_axis, float(csp_axis.arm.q[0]) + 0.5)  # far ahead; the plant is not stepped here
    for k in range(20):  # 20 ms of SYNCs
        csp_axis.cycle(k * 0.001, 0.001)
    assert (csp_axis.sm.state is State.FAULT) is faults
    assert (csp_axis.fault_code == 0x8611) is faults


@pytest.mark.parametrize("delay_s", [0.002, NEVER])
def test_the_mode_display_follows_0x6060_after_its_delay(delay_s: float) -> None:
    """0x6061 shows a new mode only `mode_display_delay_s` after 0x6060 was written (a real
    drive's few ms; NEVER: a drive that does not switch), and the drive runs in the mode shown."""
    cfg = with_backend(load_robot_config(UR5E), "sim")
    node = SlaveNode(1, str(eds("ros_canopen/Elmo.dcf")), lambda msg: None)
    node.boot(0.0)
    axis = Axis(
        node,
        0,
        DriveTrainArm(cfg, RobotModel.from_config(cfg)),
        UNITS,
        Strictness(mode_display_delay_s=delay_s),
    )
    axis.boot()
    before = node.get(0x6061)
    assert before != MODE_CST
    sdo_write(node, 0x6060, 0, MODE_CST, 1)  # at t = 0
    axis.poll(0.001)
    assert node.get(0x6061) == before and axis._mode() == before
    axis.poll(0.0025)
    assert node.get(0x6061) == (before if delay_s == NEVER else MODE_CST)
