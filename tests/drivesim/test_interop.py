"""The drive simulator in its own process, on the userspace hub, against stock clients: the
`canopen` library's SDO client and raw frames from python-can (issue 40, "interop with
independent devices")."""

from __future__ import annotations

import logging
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import can
import canopen
import pytest

from orccadd.vcan.process import HOST
from tests.canopen_rig import Rig, canopen_rig

logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)

NODE = 1
MODE_CSP, MODE_CSV, MODE_CST, MODE_VL = 8, 9, 10, 2  # the Elmo's 0x6502 (0x3ED) lacks vl (bit 1)


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    with canopen_rig(tmp_path_factory.mktemp("interop")) as r:
        yield r


def _hub_port(rig: Rig) -> int:
    if rig.hub is None:
        pytest.skip("the kernel's vcan0: these tests reach the drives through the userspace hub")
    return rig.hub.port


@pytest.fixture
def node(rig: Rig) -> Iterator[canopen.RemoteNode]:
    """Stock canopen's SDO client on node 1, over python-can's socketcand interface."""
    network = canopen.Network()
    network.connect(interface="socketcand", channel="can0", host=HOST, port=_hub_port(rig))
    try:
        remote = canopen.RemoteNode(NODE, str(_description(rig)))
        network.add_node(remote)
        remote.sdo.RESPONSE_TIMEOUT = 2.0
        yield remote
    finally:
        network.disconnect()


def _description(rig: Rig) -> Path:
    return next(Path(rig.config).parent.glob("*.dcf"))


def test_the_mode_display_shows_a_confirmed_mode_at_once(node: canopen.RemoteNode) -> None:
    """0x6060 written and confirmed, then 0x6061 read at once: never the old mode (a real drive
    takes a mode within its own cycle, before it confirms the write). 50 changes, each to a mode
    other than the one shown."""
    wrong = []
    for k in range(50):
        mode = (MODE_CSP, MODE_CSV, MODE_CST)[k % 3]
        node.sdo[0x6060].raw = mode
        shown = node.sdo[0x6061].raw
        if shown != mode:
            wrong.append((k, mode, shown))
    assert not wrong, f"0x6061 showed the old mode after a confirmed write: {wrong}"


def test_a_mode_the_drive_does_not_support_is_aborted_and_not_shown(node: canopen.RemoteNode) -> None:
    node.sdo[0x6060].raw = MODE_CSP
    with pytest.raises(canopen.SdoAbortedError) as e:
        node.sdo[0x6060].raw = MODE_VL
    assert e.value.code == 0x06090030  # value range of parameter exceeded
    assert node.sdo[0x6060].raw == MODE_CSP
    assert node.sdo[0x6061].raw == MODE_CSP


@pytest.fixture
def raw_bus(rig: Rig) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="socketcand", channel="can0", host=HOST, port=_hub_port(rig))
    try:
        yield bus
    finally:
        bus.shutdown()


def _sdo_answer(bus: can.BusABC, request: bytes, timeout_s: float = 5.0) -> bytes:
    """Send an SDO request to node 1 and return its answer (other frames skipped)."""
    while bus.recv(0.0) is not None:  # what came before is not the answer
        pass
    bus.send(can.Message(arbitration_id=0x600 + NODE, data=request, is_extended_id=False))
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        msg = bus.recv(0.2)
        if msg is not None and msg.arbitration_id == 0x580 + NODE:
            return bytes(msg.data)
    raise AssertionError(f"node {NODE} did not answer {request.hex()} within {timeout_s:g} s")


def _unsized(index: int, data: bytes) -> bytes:
    """An expedited download without a size indication (e = 1, s = 0: command 0x22)."""
    return struct.pack("<BHB", 0x22, index, 0) + data


def test_an_unsized_expedited_download_to_a_16_bit_object_is_taken_and_logged(
    rig: Rig, raw_bus: can.BusABC
) -> None:
    """CiA 301 lets a client leave the size out of an expedited download (e = 1, s = 0): the
    drive takes the object's own 2 bytes of the 4, and says so in its log, naming the object.
    Bytes beyond the object's size that are not zero would be lost: aborted (0x06070012)."""
    answer = _sdo_answer(raw_bus, _unsized(0x6066, (123).to_bytes(4, "little")))
    assert answer[0] == 0x60 and answer[1:4] == struct.pack("<HB", 0x6066, 0), answer.hex()
    read = _sdo_answer(raw_bus, struct.pack("<BHB4x", 0x40, 0x6066, 0))
    assert read[0] == 0x4B and struct.unpack_from("<H", read, 4)[0] == 123, read.hex()
    end = time.monotonic() + 5.0
    while "0x6066:00" not in rig.drives.log_text() and time.monotonic() < end:
        time.sleep(0.05)
    logged = [line for line in rig.drives.log_text().splitlines() if "0x6066:00" in line]
    assert logged and "without a size indication" in logged[0], rig.drives.log_text(2000)
    answer = _sdo_answer(raw_bus, _unsized(0x6066, (0x10000 + 5).to_bytes(4, "little")))
    assert answer[0] == 0x80 and struct.unpack_from("<I", answer, 4)[0] == 0x06070012, answer.hex()
    read = _sdo_answer(raw_bus, struct.pack("<BHB4x", 0x40, 0x6066, 0))
    assert struct.unpack_from("<H", read, 4)[0] == 123  # unchanged
