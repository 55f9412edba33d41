"""The simulated drive as strict as CiA 301/402 let a real one be: the mode of operation taken
before its write is confirmed, only modes 0x6502 lists, PDO mappings only in CiA 301's order,
an expedited download without a size indication taken and logged (docs/simulators.md, "drivesim
where CiA 301 and CiA 402 leave room")."""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator

import can
import canopen
import pytest

from orccadd.drivesim.axis import Axis, AxisUnits, supports_mode
from orccadd.drivesim.plant import DriveTrainArm
from orccadd.drivesim.slave import SlaveNode
from orccadd.model import RobotModel
from orccadd.robot import load_robot_config, with_backend
from tests.conftest import UR5E, eds
from tests.drivesim.test_slave import Harness

UNITS = AxisUnits(counts_per_rev=4096, gear_ratio=100.0, rated_torque_nm=0.5)
ELMO = "ros_canopen/Elmo.dcf"  # 0x6502 = 0x3ED: pp, pv, tq, hm, ip, csp, csv, cst (no vl, mode 2)
INVALID = 1 << 31


class Drive:
    """One axis behind its node, no bus: frames in by `sdo`, every frame out kept in `sent` with
    what 0x6061 showed as it left."""

    def __init__(self, eds_file: str = ELMO) -> None:
        cfg = with_backend(load_robot_config(UR5E), "sim")
        self.sent: list[tuple[can.Message, int]] = []
        self.node = SlaveNode(1, str(eds(eds_file)), self._send)
        self.node.boot(0.0)
        self.axis = Axis(self.node, 0, DriveTrainArm(cfg, RobotModel.from_config(cfg)), UNITS)
        self.axis.boot()

    def _send(self, msg: can.Message) -> None:
        self.sent.append((msg, self.node.values.get((0x6061, 0), 0)))

    def sdo(self, request: bytes, cob: int = 0x601) -> bytes:
        """The node's answer to `request` (an SDO frame's 8 bytes)."""
        self.sent.clear()
        self.node.on_frame(can.Message(arbitration_id=cob, data=request, is_extended_id=False), 0.0)
        answers = [m for m, _ in self.sent if m.arbitration_id == 0x581]
        assert len(answers) == 1, self.sent
        return bytes(answers[0].data)


def download(index: int, sub: int, value: int, size: int, signed: bool = False) -> bytes:
    """An expedited SDO download with its size indicated, as canopen sends it."""
    body = value.to_bytes(size, "little", signed=signed).ljust(4, b"\0")
    return struct.pack("<BHB", 0x23 | (4 - size) << 2, index, sub) + body


def abort_code(answer: bytes) -> int:
    assert answer[0] == 0x80, answer.hex()
    return int(struct.unpack_from("<I", answer, 4)[0])


# ---- the mode of operation --------------------------------------------------------------------
def test_a_mode_is_shown_before_its_write_is_confirmed() -> None:
    drive = Drive()
    for mode in (8, 9, 10, 8):
        assert drive.sdo(download(0x6060, 0, mode, 1))[0] == 0x60
        (confirmation,) = [(m, shown) for m, shown in drive.sent if m.arbitration_id == 0x581]
        assert confirmation[1] == mode  # 0x6061 as the confirmation left the drive


@pytest.mark.parametrize("mode", [2, 5, 11, -1])
def test_a_mode_0x6502_does_not_list_is_aborted_and_nothing_changes(mode: int) -> None:
    drive = Drive()
    drive.sdo(download(0x6060, 0, 8, 1))
    answer = drive.sdo(download(0x6060, 0, mode, 1, signed=True))
    # 11 is beyond the description's range of 0x6060 (-128..10): "value too high" comes first
    assert abort_code(answer) == (0x06090031 if mode == 11 else 0x06090030)
    assert drive.node.get(0x6060) == 8 and drive.node.get(0x6061) == 8


def test_a_mode_refused_in_an_rpdo_is_ignored() -> None:
    """An RPDO has no one to abort to: the refused mode is not taken, 0x6060 and 0x6061 stay."""
    drive = Drive()
    node = drive.node
    rpdo = node.rpdos[0x1400]
    for step in (
        download(0x1400, 1, rpdo.cob_id | INVALID, 4),
        download(0x1600, 0, 0, 1),
        download(0x1600, 1, 0x60600008, 4),
        download(0x1600, 0, 1, 1),
        download(0x1400, 2, 255, 1),  # applied at once
        download(0x1400, 1, rpdo.cob_id, 4),
    ):
        assert drive.sdo(step)[0] == 0x60, step.hex()
    node.on_frame(can.Message(arbitration_id=0x000, data=b"\x01\x01", is_extended_id=False), 0.0)
    for mode, shown in ((9, 9), (2, 9), (10, 10)):
        node.on_frame(can.Message(arbitration_id=rpdo.cob_id, data=bytes([mode]), is_extended_id=False), 0.0)
        assert node.get(0x6061) == shown and node.get(0x6060) == shown


@pytest.mark.parametrize(
    ("supported", "mode", "listed"),
    [
        (0x3ED, 8, True),
        (0x3ED, 2, False),  # vl: bit 1
        (0x3ED, 1, True),
        (0x380, 7, False),
        (0x380, 10, True),
        (0x380, 0, True),  # no mode assigned
        (0x30000, -1, True),  # manufacturer's bits 16, 17: modes -1, -2
        (0x30000, -2, True),
        (0x30000, -3, False),
        (0x380, 17, False),  # bit 16 is the manufacturer's, not mode 17's
        (0, 2, True),  # 0x6502 left empty: says nothing
    ],
)
def test_supported_drive_modes_bits(supported: int, mode: int, listed: bool) -> None:
    assert supports_mode(supported, mode) is listed


# ---- PDO mapping in CiA 301's order --------------------------------------------------------------
@pytest.fixture
def h() -> Iterator[Harness]:
    harness = Harness(str(eds(ELMO)))
    try:
        yield harness
    finally:
        harness.close()


def refused(h: Harness, index: int, sub: int, value: int) -> int:
    with pytest.raises(canopen.SdoAbortedError) as e:
        h.master.sdo[index][sub].raw = value
    return int(e.value.code)


def test_a_stock_client_writing_the_count_of_a_valid_rpdo_is_refused(h: Harness) -> None:
    """0x1600 sub 0 while RPDO1 is valid (bit 31 of 0x1400 sub 1 clear): 0x06010000, as an
    entry is; the mapping stays."""
    before = list(h.node.rpdos[0x1400].entries)
    assert h.node.rpdos[0x1400].valid
    assert refused(h, 0x1600, 0, 0) == 0x06010000
    assert refused(h, 0x1600, 1, 0x60400010) == 0x06010000
    assert h.node.rpdos[0x1400].entries == before


def test_an_entry_while_the_count_is_not_zero_is_refused(h: Harness) -> None:
    h.master.sdo[0x1400][1].raw = h.node.rpdos[0x1400].cob_id | INVALID
    assert h.node.get(0x1600, 0) != 0
    assert refused(h, 0x1600, 1, 0x60400010) == 0x06010000


@pytest.mark.parametrize(
    ("entries", "count", "code"),
    [
        ((0x607A0020, 0x60FF0020, 0x60400010), 3, 0x06040042),  # 80 bits
        ((0x60400010,), 9, 0x06040042),  # beyond the 8 entries 0x1600 has
        ((0x55550010,), None, 0x06020000),  # no such object (step c)
        ((0x10000020,), None, 0x06040041),  # device type: not mappable
        ((0x60400020,), None, 0x06040041),  # the controlword is 16 bits, not 32
    ],
)
def test_mapping_checks_name_cia_301_codes(
    h: Harness, entries: tuple[int, ...], count: int | None, code: int
) -> None:
    h.master.sdo[0x1400][1].raw = h.node.rpdos[0x1400].cob_id | INVALID
    h.master.sdo[0x1600][0].raw = 0
    for sub, entry in enumerate(entries, 1):
        if count is None:
            assert refused(h, 0x1600, sub, entry) == code
            return
        h.master.sdo[0x1600][sub].raw = entry
    assert refused(h, 0x1600, 0, count) == code


def test_the_five_steps_in_order_are_taken(h: Harness) -> None:
    cob = h.node.rpdos[0x1400].cob_id
    for index, sub, value in (
        (0x1400, 1, cob | INVALID),
        (0x1600, 0, 0),
        (0x1600, 1, 0x60400010),
        (0x1600, 2, 0x607A0020),
        (0x1600, 0, 2),
        (0x1400, 1, cob),
    ):
        h.master.sdo[index][sub].raw = value
    assert h.node.rpdos[0x1400].valid
    assert h.node.rpdos[0x1400].entries == [(0x6040, 0, 16), (0x607A, 0, 32)]


# ---- an expedited download without a size indication ---------------------------------------------
def unsized(index: int, data: bytes) -> bytes:
    return struct.pack("<BHB", 0x22, index, 0) + data


@pytest.mark.parametrize(
    ("index", "data", "value"),
    [
        (0x6066, b"\x7b\x00\x00\x00", 123),  # UNSIGNED16
        (0x6060, b"\x0a\x00\x00\x00", 10),  # INTEGER8
        (0x6060, b"\xf8\xff\xff\xff", None),  # INTEGER8 -8, sign-extended: taken, then 0x6502 says no
        (0x607A, b"\x18\xfc\xff\xff", -1000),  # INTEGER32: all 4 bytes are the value
    ],
)
def test_an_unsized_expedited_download_takes_the_object_size_and_is_logged_once(
    caplog: pytest.LogCaptureFixture, index: int, data: bytes, value: int | None
) -> None:
    drive = Drive()
    with caplog.at_level(logging.WARNING, logger="orccadd.drivesim"):
        answers = [drive.sdo(unsized(index, data)) for _ in range(2)]
    if value is None:
        assert [abort_code(a) for a in answers] == [0x06090030] * 2
    else:
        assert [a[0] for a in answers] == [0x60, 0x60]
        assert drive.node.get(index) == value
    logged = [r.getMessage() for r in caplog.records if f"0x{index:04X}:00" in r.getMessage()]
    assert len(logged) == 1 and "without a size indication (e=1, s=0)" in logged[0], logged


@pytest.mark.parametrize(
    ("index", "data"),
    [
        (0x6066, b"\x05\x00\x01\x00"),  # 0x10005 into 16 bits
        (0x6060, b"\x08\x00\x00\x01"),
        (0x6060, b"\x08\xff\xff\xff"),  # not the sign extension of a positive value
    ],
)
def test_an_unsized_download_whose_extra_bytes_are_not_padding_is_aborted(index: int, data: bytes) -> None:
    drive = Drive()
    before = drive.node.get(index)
    assert abort_code(drive.sdo(unsized(index, data))) == 0x06070012
    assert drive.node.get(index) == before
