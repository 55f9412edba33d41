"""The CoE mailbox server against requests laid out as SOEM 1.1.13's ethercatcoe.c builds them
(`ec_SDOt` over `ec_mbxheadert`), its answers read as SOEM reads them: expedited, normal and
segmented uploads and downloads, complete access as `ec_PDOdesct`, every abort code, the mailbox
counter, mailbox errors and an emergency's bytes."""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from orccadd.drivesim.objects import ObjectStore
from orccadd.ecatsim.coe import CoeServer
from tests.conftest import ROOT

EDS = str(ROOT / "configs" / "eds" / "orccadd-cia402.eds")

# ethercattype.h / ethercatmain.h / ethercatcoe.c
MBX_HEADER = struct.Struct("<HHBB")  # ec_mbxheadert: length, address, priority, mbxtype
CANOPEN = struct.Struct("<H")  # ec_SDOt.CANOpen: number bits 0-8, service bits 12-15
SDO_FIELDS = struct.Struct("<BHB")  # ec_SDOt: Command, Index, SubIndex; then ldata[]
ECT_MBXT_ERR, ECT_MBXT_EOE, ECT_MBXT_COE = 0x00, 0x02, 0x03
ECT_COES_EMERGENCY, ECT_COES_SDOREQ, ECT_COES_SDORES, ECT_COES_SDOINFO = 0x01, 0x02, 0x03, 0x08
ECT_SDO_DOWN_INIT, ECT_SDO_DOWN_EXP, ECT_SDO_DOWN_INIT_CA = 0x21, 0x23, 0x31
ECT_SDO_UP_REQ, ECT_SDO_UP_REQ_CA, ECT_SDO_SEG_UP_REQ, ECT_SDO_ABORT = 0x40, 0x50, 0x60, 0x80
PDO_DESC = struct.Struct("<BB8I")  # ec_PDOdesct: uint8 n; uint8 nu1; uint32 PDO[] (8 of 256 here)


@dataclass(frozen=True)
class Answer:
    """A message the slave posted, read through SOEM's `ec_SDOt` (or `ec_mbxerrort`) overlay."""

    raw: bytes
    length: int
    mbxtype: int
    counter: int
    service: int
    command: int
    index: int
    subindex: int

    @property
    def ldata0(self) -> int:
        return int.from_bytes(self.raw[12:16], "little")


def answer(raw: bytes, mbx_l: int) -> Answer:
    assert len(raw) <= mbx_l, "posted longer than the mailbox"
    raw = raw.ljust(mbx_l, b"\x00")  # the ESC pads SM1; SOEM reads all mbx_rl bytes
    length, _address, _priority, mbxtype = MBX_HEADER.unpack_from(raw)
    (canopen,) = CANOPEN.unpack_from(raw, 6)
    command, index, subindex = SDO_FIELDS.unpack_from(raw, 8)
    return Answer(raw, length, mbxtype & 0x0F, mbxtype >> 4, canopen >> 12, command, index, subindex)


class SlaveAbortError(Exception):
    """The slave answered with an abort (ecx_SDOerror's case)."""

    def __init__(self, code: int) -> None:
        super().__init__(f"abort 0x{code:08X}")
        self.code = code


class Soem:
    """The master's side of ecx_SDOread/ecx_SDOwrite, one mailbox exchange at a time, against a
    server over the project's CiA 402 description."""

    def __init__(self, mbx_l: int = 128) -> None:
        self.mbx_l = mbx_l
        self.store = ObjectStore(EDS, 1)
        self.posted: list[bytes] = []
        self.server = CoeServer(self.store, self.posted.append, mbx_l)
        self.mbx_cnt = 0

    def next_cnt(self) -> int:  # ec_nextmbxcnt
        self.mbx_cnt = 1 if self.mbx_cnt + 1 > 7 else self.mbx_cnt + 1
        return self.mbx_cnt

    def send(
        self, length: int, canopen: int, body: bytes, mbxtype: int = ECT_MBXT_COE, cnt: int | None = None
    ) -> list[Answer]:
        """One mailbox written (ecx_mbxsend writes all mbx_l bytes of a cleared buffer): what came back."""
        cnt = self.next_cnt() if cnt is None else cnt
        mbx = MBX_HEADER.pack(length, 0, 0, mbxtype + (cnt << 4)) + CANOPEN.pack(canopen) + body
        self.server.on_mailbox(mbx.ljust(self.mbx_l, b"\x00"))
        out = [answer(raw, self.mbx_l) for raw in self.posted]
        self.posted.clear()
        return out

    def sdo(
        self, length: int, command: int, index: int, sub: int, ldata: bytes = bytes(4), cnt: int | None = None
    ) -> list[Answer]:
        body = SDO_FIELDS.pack(command, index, sub) + ldata
        return self.send(length, ECT_COES_SDOREQ << 12, body, cnt=cnt)

    def one(self, length: int, command: int, index: int, sub: int, ldata: bytes = bytes(4)) -> Answer:
        (a,) = self.sdo(length, command, index, sub, ldata)
        return a

    def read(self, index: int, sub: int, ca: bool = False) -> bytes:
        """ecx_SDOread: the parameter's bytes, or SlaveAbortError."""
        if ca and sub > 1:
            sub = 1
        a = self.one(0x0A, ECT_SDO_UP_REQ_CA if ca else ECT_SDO_UP_REQ, index, sub)
        if not (a.mbxtype == ECT_MBXT_COE and a.service == ECT_COES_SDORES and a.index == index):
            raise self._unexpected(a)
        if a.command & 0x02:  # expedited
            return a.raw[12 : 12 + 4 - ((a.command >> 2) & 0x03)]
        sdo_len = a.ldata0
        frame = a.length - 10
        if frame >= sdo_len:
            return a.raw[16 : 16 + sdo_len]
        out = bytearray(a.raw[16 : 16 + frame])
        toggle = 0x00
        while True:
            s = self.one(0x0A, ECT_SDO_SEG_UP_REQ + toggle, index, sub)
            if not (s.mbxtype == ECT_MBXT_COE and s.service == ECT_COES_SDORES and s.command & 0xE0 == 0):
                raise self._unexpected(s)
            n = s.length - 3
            if s.command & 0x01:
                if n == 7:
                    n -= (s.command & 0x0E) >> 1
                out += s.raw[9 : 9 + n]
                return bytes(out)
            out += s.raw[9 : 9 + n]
            toggle ^= 0x10

    def write(self, index: int, sub: int, data: bytes, ca: bool = False) -> None:
        """ecx_SDOwrite: returns, or SlaveAbortError."""
        maxdata = self.mbx_l - 0x10
        if len(data) <= 4 and not ca:
            command = ECT_SDO_DOWN_EXP | (((4 - len(data)) << 2) & 0x0C)
            a = self.one(0x0A, command, index, sub, data.ljust(4, b"\x00"))
            if not (
                a.mbxtype == ECT_MBXT_COE
                and a.service == ECT_COES_SDORES
                and (a.index, a.subindex) == (index, sub)
            ):
                raise self._unexpected(a)
            return
        frame, not_last = (maxdata, True) if len(data) > maxdata else (len(data), False)
        sub = 1 if ca and sub > 1 else sub
        command = ECT_SDO_DOWN_INIT_CA if ca else ECT_SDO_DOWN_INIT
        a = self.one(0x0A + frame, command, index, sub, struct.pack("<I", len(data)) + data[:frame])
        if not (
            a.mbxtype == ECT_MBXT_COE
            and a.service == ECT_COES_SDORES
            and (a.index, a.subindex) == (index, sub)
        ):
            raise self._unexpected(a)
        hp, maxdata, toggle = frame, maxdata + 7, 0
        while not_last:
            frame, not_last, command = len(data) - hp, False, 0x01
            if frame > maxdata:
                frame, not_last, command = maxdata, True, 0x00
            if not not_last and frame < 7:
                length, command = 0x0A, 0x01 + ((7 - frame) << 1)
            else:
                length = frame + 3
            chunk = data[hp : hp + frame]
            hp += frame
            (s,) = self.send(length, ECT_COES_SDOREQ << 12, bytes([command + toggle]) + chunk)
            if not (s.mbxtype == ECT_MBXT_COE and s.service == ECT_COES_SDORES and s.command & 0xE0 == 0x20):
                raise self._unexpected(s)
            toggle ^= 0x10

    @staticmethod
    def _unexpected(a: Answer) -> Exception:
        if a.command == ECT_SDO_ABORT:
            return SlaveAbortError(a.ldata0)
        return AssertionError(f"unexpected frame: {a.raw.hex(' ')}")


def abort_code(call: Callable[..., object], *args: object, **kwargs: object) -> int:
    with pytest.raises(SlaveAbortError) as e:
        call(*args, **kwargs)
    return e.value.code


# ---- upload ------------------------------------------------------------------------------------------
def test_an_expedited_upload_carries_the_value_in_the_4_data_bytes() -> None:
    soem = Soem()
    a = soem.one(0x0A, ECT_SDO_UP_REQ, 0x1000, 0)
    assert (a.length, a.mbxtype, a.service, a.command) == (0x0A, ECT_MBXT_COE, ECT_COES_SDORES, 0x43)
    assert (a.index, a.subindex, a.ldata0) == (0x1000, 0, 0x00020192)
    b = soem.one(0x0A, ECT_SDO_UP_REQ, 0x6060, 0)  # INTEGER8: 3 bytes unused
    assert b.command == 0x43 | 3 << 2 and b.raw[12] == 8
    assert soem.read(0x6060, 0) == b"\x08" and soem.read(0x1A00, 1) == struct.pack("<I", 0x60410010)


def test_complete_access_reads_a_pdo_mapping_as_ec_pdodesct() -> None:
    soem = Soem()
    a = soem.one(0x0A, ECT_SDO_UP_REQ_CA, 0x1A00, 0)
    assert a.command == 0x41 | 0x10 and a.ldata0 == 2 + 2 * 4 and a.length == 10 + 10  # normal, all of it
    desc = soem.read(0x1A00, 0, ca=True).ljust(PDO_DESC.size, b"\x00")
    n, nu1, *pdo = PDO_DESC.unpack(desc)
    assert (n, nu1, pdo[:2]) == (2, 0, [0x60410010, 0x60640020])  # sub 0 in a 16-bit slot
    assert sum(p & 0xFF for p in pdo[:n]) == 48  # ecx_readPDOassignCA's bit length
    assert soem.read(0x1A00, 1, ca=True) == struct.pack("<2I", 0x60410010, 0x60640020)  # sub 0 left out


@pytest.mark.parametrize("mbx_l", [24, 28, 26, 40])
def test_an_object_larger_than_the_mailbox_is_uploaded_in_segments(mbx_l: int) -> None:
    soem = Soem(mbx_l)
    entries = [0x60400010, 0x60600008, 0x607A0020, 0x60FF0020, 0x60710010, 0x60B20010, 0x60C20108, 0x60770010]
    soem.store.set(0x1A01, 0, 8)
    for sub, entry in enumerate(entries, 1):
        soem.store.set(0x1A01, sub, entry)
    expected = bytes([8, 0]) + struct.pack("<8I", *entries)  # 34 bytes
    first = soem.one(0x0A, ECT_SDO_UP_REQ_CA, 0x1A01, 0)
    assert first.ldata0 == 34 and first.length - 10 == mbx_l - 16
    soem.server.reset()
    soem.mbx_cnt = 0
    assert soem.read(0x1A01, 0, ca=True) == expected


def test_the_segments_of_an_upload_alternate_their_toggle_and_flag_the_last() -> None:
    soem = Soem(28)  # 12 bytes in the first answer, then 19 a segment: 19, then 3 padded to 7
    soem.store.set(0x1A00, 0, 8)
    soem.one(0x0A, ECT_SDO_UP_REQ_CA, 0x1A00, 0)
    s1 = soem.one(0x0A, ECT_SDO_SEG_UP_REQ, 0x1A00, 0)
    assert (s1.command, s1.length) == (0x00, 3 + 19)
    s2 = soem.one(0x0A, ECT_SDO_SEG_UP_REQ + 0x10, 0x1A00, 0)
    assert (s2.command, s2.length) == (0x10 | 4 << 1 | 0x01, 0x0A)  # 4 bytes unused, last


# ---- download ----------------------------------------------------------------------------------------
def test_an_expedited_download_stores_the_value_and_is_confirmed() -> None:
    soem = Soem()
    a = soem.one(0x0A, ECT_SDO_DOWN_EXP | 2 << 2, 0x6040, 0, b"\x0f\x00\x00\x00")
    assert (a.service, a.command, a.index, a.subindex) == (ECT_COES_SDORES, 0x60, 0x6040, 0)
    assert soem.store.get(0x6040) == 0x0F
    soem.write(0x607A, 0, struct.pack("<i", -5000))
    assert soem.store.get(0x607A) == -5000


def test_an_expedited_download_without_size_takes_the_object_size() -> None:
    soem = Soem()
    a = soem.one(0x0A, 0x22, 0x6066, 0, b"\x7b\x00\x00\x00")
    assert a.command == 0x60 and soem.store.get(0x6066) == 123


def test_a_normal_download_carries_the_complete_size_and_the_data() -> None:
    soem = Soem()
    a = soem.one(0x0A + 4, ECT_SDO_DOWN_INIT, 0x607A, 0, struct.pack("<Ii", 4, 777))
    assert (a.command, a.index, a.subindex) == (0x60, 0x607A, 0) and soem.store.get(0x607A) == 777
    soem.write(0x1A00, 0, bytes([3, 0]) + struct.pack("<3I", 0x60410010, 0x60640020, 0x606C0020), ca=True)
    assert [soem.store.get(0x1A00, s) for s in range(4)] == [3, 0x60410010, 0x60640020, 0x606C0020]


@pytest.mark.parametrize(("mbx_l", "count"), [(24, 3), (24, 8), (30, 8), (32, 5)])
def test_complete_access_larger_than_the_mailbox_is_downloaded_in_segments(mbx_l: int, count: int) -> None:
    soem = Soem(mbx_l)
    entries = [0x60400010, 0x60600008, 0x607A0020, 0x60FF0020, 0x60710010, 0x60B20010, 0x60C20108, 0x60770010]
    soem.write(0x1600, 0, bytes([count, 0]) + struct.pack(f"<{count}I", *entries[:count]), ca=True)
    assert [soem.store.get(0x1600, s) for s in range(count + 1)] == [count, *entries[:count]]


def test_the_last_download_segment_names_its_unused_bytes() -> None:
    soem = Soem(24)  # 8 bytes in the initiate request, 6 in a last segment of 7
    data = bytes([3, 0]) + struct.pack("<3I", 0x60410010, 0x60640020, 0x606C0020)
    soem.one(0x0A + 8, ECT_SDO_DOWN_INIT_CA, 0x1A00, 0, struct.pack("<I", 14) + data[:8])
    (s,) = soem.send(0x0A, ECT_COES_SDOREQ << 12, bytes([0x01 + (1 << 1)]) + data[8:] + b"\x00")
    assert s.command == 0x20 and soem.store.get(0x1A00, 3) == 0x606C0020


# ---- aborts ------------------------------------------------------------------------------------------
def test_an_abort_is_an_sdo_request_with_the_code_as_soem_reads_it() -> None:
    soem = Soem()
    a = soem.one(0x0A, ECT_SDO_UP_REQ, 0x2000, 0)
    # service "SDO request", so ecx_SDOread's first test fails and it reads Command and ldata[0]
    assert (a.mbxtype, a.service, a.command, a.index, a.subindex) == (
        ECT_MBXT_COE,
        ECT_COES_SDOREQ,
        0x80,
        0x2000,
        0,
    )
    assert a.length == 0x0A and a.ldata0 == 0x06020000


@pytest.mark.parametrize(
    ("index", "sub", "code"),
    [(0x2000, 0, 0x06020000), (0x1A00, 9, 0x06090011)],
)
def test_a_missing_object_or_subindex(index: int, sub: int, code: int) -> None:
    soem = Soem()
    assert abort_code(soem.read, index, sub) == code
    assert abort_code(soem.write, index, sub, b"\x01") == code


def test_read_only_write_only_length_and_range() -> None:
    soem = Soem()
    assert abort_code(soem.write, 0x1000, 0, b"\x00\x00\x00\x00") == 0x06010002
    soem.store.vars[(0x6040, 0)].access_type = "wo"
    assert abort_code(soem.read, 0x6040, 0) == 0x06010001
    assert abort_code(soem.write, 0x607A, 0, b"\x01\x02") == 0x06070010  # 2 bytes for 32 bits
    assert abort_code(soem.write, 0x1A00, 0, b"\x09") == 0x06090031  # HighLimit 8
    soem.store.vars[(0x6066, 0)].min = 10
    assert abort_code(soem.write, 0x6066, 0, b"\x09\x00") == 0x06090032
    assert soem.store.get(0x1A00) == 2 and soem.store.get(0x6066) == 0


def test_a_toggle_out_of_turn_aborts_and_ends_the_transfer() -> None:
    soem = Soem(24)
    soem.one(0x0A, ECT_SDO_UP_REQ_CA, 0x1A00, 0)
    soem.store.set(0x1A00, 0, 8)
    soem.one(0x0A, ECT_SDO_UP_REQ_CA, 0x1A00, 0)
    a = soem.one(0x0A, ECT_SDO_SEG_UP_REQ + 0x10, 0x1A00, 0)
    assert (a.command, a.ldata0, a.index) == (0x80, 0x05030000, 0x1A00)
    b = soem.one(0x0A, ECT_SDO_SEG_UP_REQ, 0x1A00, 0)  # nothing under way any more
    assert (b.command, b.ldata0) == (0x80, 0x05040001)


@pytest.mark.parametrize("command", [0xA0, 0xC0, 0xE0])  # block download, block upload, reserved
def test_an_unknown_command_aborts(command: int) -> None:
    a = Soem().one(0x0A, command, 0x1000, 0)
    assert (a.command, a.index, a.ldata0) == (0x80, 0x1000, 0x05040001)


def test_an_abort_from_the_master_ends_the_transfer_unanswered() -> None:
    soem = Soem(24)
    soem.store.set(0x1A00, 0, 8)
    soem.one(0x0A, ECT_SDO_UP_REQ_CA, 0x1A00, 0)
    assert soem.sdo(0x0A, ECT_SDO_ABORT, 0x1A00, 0, struct.pack("<I", 0x05040000)) == []
    a = soem.one(0x0A, ECT_SDO_SEG_UP_REQ, 0x1A00, 0)
    assert (a.command, a.ldata0) == (0x80, 0x05040001)


def test_a_download_segment_longer_than_announced_aborts() -> None:
    soem = Soem(24)
    soem.one(0x0A + 8, ECT_SDO_DOWN_INIT_CA, 0x1A00, 0, struct.pack("<I", 10) + bytes(8))
    (a,) = soem.send(3 + 9, ECT_COES_SDOREQ << 12, b"\x01" + bytes(9))
    assert (a.command, a.index, a.ldata0) == (0x80, 0x1A00, 0x06070012)


# ---- the mailbox -------------------------------------------------------------------------------------
def test_a_repeated_counter_is_ignored_and_answers_count_1_to_7() -> None:
    soem = Soem()
    assert len(soem.sdo(0x0A, ECT_SDO_UP_REQ, 0x1000, 0, cnt=3)) == 1
    assert soem.sdo(0x0A, ECT_SDO_UP_REQ, 0x1000, 0, cnt=3) == []  # the master's repeat
    assert len(soem.sdo(0x0A, ECT_SDO_UP_REQ, 0x1000, 0, cnt=0)) == 1  # 0: never a repeat
    assert len(soem.sdo(0x0A, ECT_SDO_UP_REQ, 0x1000, 0, cnt=0)) == 1
    counters = [soem.one(0x0A, ECT_SDO_UP_REQ, 0x1000, 0).counter for _ in range(8)]
    assert counters == [4, 5, 6, 7, 1, 2, 3, 4]


@pytest.mark.parametrize(
    ("length", "mbxtype", "canopen", "detail"),
    [
        (0x0A, ECT_MBXT_EOE, ECT_COES_SDOREQ << 12, 0x0002),  # not CoE: unsupported protocol
        (0x08, ECT_MBXT_COE, ECT_COES_SDOINFO << 12, 0x0004),  # SDO information: service not supported
        (0x0A, ECT_MBXT_COE, ECT_COES_SDORES << 12, 0x0004),
        (0x06, ECT_MBXT_COE, ECT_COES_SDOREQ << 12, 0x0006),  # too short for a SDO request
        (0x01, ECT_MBXT_COE, ECT_COES_SDOREQ << 12, 0x0006),  # too short for the CoE header
        (128, ECT_MBXT_COE, ECT_COES_SDOREQ << 12, 0x0008),  # beyond the mailbox
    ],
)
def test_what_is_not_served_gets_a_mailbox_error(
    length: int, mbxtype: int, canopen: int, detail: int
) -> None:
    soem = Soem()
    (a,) = soem.send(length, canopen, SDO_FIELDS.pack(ECT_SDO_UP_REQ, 0x1000, 0) + bytes(4), mbxtype)
    # ec_mbxerrort: the header, Type, Detail
    assert (a.mbxtype, a.length, a.counter) == (ECT_MBXT_ERR, 4, 1)
    assert struct.unpack_from("<HH", a.raw, 6) == (0x0001, detail)


def test_a_channel_other_than_0_gets_a_mailbox_error() -> None:
    soem = Soem()
    mbx = MBX_HEADER.pack(0x0A, 0, 0x05, ECT_MBXT_COE | 1 << 4) + CANOPEN.pack(ECT_COES_SDOREQ << 12)
    soem.server.on_mailbox((mbx + SDO_FIELDS.pack(ECT_SDO_UP_REQ, 0x1000, 0)).ljust(128, b"\x00"))
    (raw,) = soem.posted
    assert raw == MBX_HEADER.pack(4, 0, 0, ECT_MBXT_ERR | 1 << 4) + struct.pack("<HH", 0x0001, 0x0003)


def test_an_emergency_is_posted_as_ec_emcyt_and_sets_the_error_register() -> None:
    soem = Soem()
    soem.server.emergency(0x8611, 0x81, b"\x01\x02\x03")
    (raw,) = soem.posted
    assert raw == bytes.fromhex("0a00 0000 00 13 0010 1186 81 0102030000")
    _header, canopen, code, reg, b_data, w1, w2 = struct.unpack("<6sHHBBHH", raw)  # ec_emcyt
    assert (canopen >> 12, code, reg, b_data, w1, w2) == (ECT_COES_EMERGENCY, 0x8611, 0x81, 1, 0x0302, 0)
    assert soem.store.get(0x1001) == 0x81
