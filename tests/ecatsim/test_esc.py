"""One ESC and a line of them, without a wire: the SII image, the registers' write masks, the AL
state rules and their status codes, the EEPROM interface, the mailbox and buffered sync managers
(what counts in the working counter), FMMUs, the SM watchdog, addressing and working counters."""

from __future__ import annotations

import struct

from orccadd.ecatsim import registers as r
from orccadd.ecatsim import sii
from orccadd.ecatsim.chain import Chain
from orccadd.ecatsim.esc import Esc
from orccadd.ecatsim.frame import Command, Datagram
from orccadd.ecatsim.registers import AlState, AlStatusCode

MBX_OUT, MBX_IN, OUT, IN = 0x1000, 0x1080, 0x1100, 0x1180


class App:
    """A firmware that takes every change and records what the ESC hands it."""

    def __init__(self, refuse: int = 0) -> None:
        self.refuse = refuse
        self.mailboxes: list[bytes] = []
        self.outputs: list[bytes] = []
        self.watchdogs = 0

    def state_change(self, current: AlState, requested: AlState) -> int:
        return self.refuse if requested is AlState.SAFE_OP else 0

    def mailbox_received(self, data: bytes) -> None:
        self.mailboxes.append(data)

    def outputs_received(self, data: bytes, now_ns: int) -> None:
        self.outputs.append(data)

    def watchdog_expired(self) -> None:
        self.watchdogs += 1


INFO = sii.SlaveInfo(
    vendor_id=0xABC,
    product_code=0x402,
    revision=7,
    serial=1,
    name="test slave",
    mailbox_out=(MBX_OUT, 128),
    mailbox_in=(MBX_IN, 128),
    sync_managers=(),
    alias=0x1234,
)


def esc(app: App | None = None) -> Esc:
    return Esc(sii.build_image(INFO), app or App())


def write_u16(e: Esc, address: int, value: int) -> bool:
    return e.write(address, struct.pack("<H", value), 0)


def mailboxes_configured(e: Esc) -> None:
    sm = r.SYNC_MANAGER.pack(MBX_OUT, 128, 0x26, 0, 1, 0) + r.SYNC_MANAGER.pack(MBX_IN, 128, 0x22, 0, 1, 0)
    assert e.write(r.SM0, sm, 0)


def test_the_sii_image_has_its_checksum_identity_and_categories() -> None:
    image = sii.build_image(INFO)
    assert image[14] == sii.crc8(image[:14])
    assert struct.unpack_from("<IIII", image, 16) == (0xABC, 0x402, 7, 1)
    assert struct.unpack_from("<4H", image, 0x18 * 2) == (MBX_OUT, 128, MBX_IN, 128)
    assert struct.unpack_from("<HH", image, 0x80) == (sii.CATEGORY_STRINGS, 6)


def test_read_only_registers_keep_their_value_and_writable_ones_take_it() -> None:
    e = esc()
    assert e.write(r.TYPE, b"\x99", 0)  # the write counts, the register does not change
    assert e.mem[r.TYPE] == 0x11
    assert write_u16(e, r.STATION_ADDRESS, 0x1001) and e.station_address == 0x1001
    assert struct.unpack_from("<H", e.mem, r.STATION_ALIAS)[0] == 0x1234  # from the SII


def test_the_eeprom_is_read_eight_bytes_at_a_time() -> None:
    e = esc()
    assert e.write(r.EEPROM_CONTROL, struct.pack("<HIH", r.EEPROM_READ, 0x08, 0), 0)
    data = bytearray(8)
    assert e.read(r.EEPROM_DATA, data, 0)
    assert struct.unpack("<II", data) == (0xABC, 0x402)
    status = struct.unpack_from("<H", e.mem, r.EEPROM_CONTROL)[0]
    assert status & r.EEPROM_READ_8_BYTES and not status & 0x8000  # never busy


def test_pre_op_needs_the_mailboxes_as_the_sii_says() -> None:
    e = esc()
    write_u16(e, r.AL_CONTROL, AlState.PRE_OP)
    assert e.mem[r.AL_STATUS] == AlState.INIT | r.AL_ERROR
    assert e.al_status_code == AlStatusCode.INVALID_MAILBOX_CONFIGURATION
    write_u16(e, r.AL_CONTROL, AlState.PRE_OP)  # not acknowledged: the error stays
    assert e.mem[r.AL_STATUS] == AlState.INIT | r.AL_ERROR
    mailboxes_configured(e)
    write_u16(e, r.AL_CONTROL, AlState.PRE_OP | r.AL_ERROR)  # acknowledged and asked again
    assert e.mem[r.AL_STATUS] == AlState.PRE_OP and e.al_status_code == 0


def test_a_jump_over_a_state_and_a_refusal_are_named() -> None:
    e = esc(App(refuse=AlStatusCode.INVALID_OUTPUT_CONFIGURATION))
    write_u16(e, r.AL_CONTROL, AlState.OP)
    assert e.al_status_code == AlStatusCode.INVALID_STATE_CHANGE
    mailboxes_configured(e)
    write_u16(e, r.AL_CONTROL, AlState.PRE_OP | r.AL_ERROR)
    write_u16(e, r.AL_CONTROL, AlState.SAFE_OP)
    assert e.mem[r.AL_STATUS] == AlState.PRE_OP | r.AL_ERROR
    assert e.al_status_code == AlStatusCode.INVALID_OUTPUT_CONFIGURATION
    write_u16(e, r.AL_CONTROL, 0x05)  # no such state
    assert e.al_status_code == AlStatusCode.INVALID_OUTPUT_CONFIGURATION  # not acknowledged: as it was


def test_a_full_mailbox_refuses_writes_and_an_empty_one_reads() -> None:
    app = App()
    e = esc(app)
    mailboxes_configured(e)
    assert e.write(MBX_OUT, bytes(range(128)), 0)
    assert app.mailboxes == [bytes(range(128))]  # taken by the firmware at once
    empty = bytearray(128)
    assert not e.read(MBX_IN, empty, 0)  # nothing to read: not counted
    e.post_mailbox(b"\x01\x02")
    e.post_mailbox(b"\x03\x04")  # waits for the first to be read
    assert e.mem[r.SM0 + 8 + 5] & r.SM_STATUS_MAILBOX_FULL
    got = bytearray(128)
    assert e.read(MBX_IN, got, 0) and got[:2] == b"\x01\x02"
    assert e.read(MBX_IN, got, 0) and got[:2] == b"\x03\x04"
    assert not e.mem[r.SM0 + 8 + 5] & r.SM_STATUS_MAILBOX_FULL
    assert not e.read(MBX_IN, got, 0)


def test_the_repeat_request_puts_the_last_message_back() -> None:
    e = esc()
    mailboxes_configured(e)
    e.post_mailbox(b"\x07\x07")
    got = bytearray(128)
    assert e.read(MBX_IN, got, 0)
    e.write(r.SM0 + 8 + 6, bytes([0x01 | r.SM_REPEAT_REQUEST]), 0)  # toggle the repeat bit
    assert e.mem[r.SM0 + 8 + 7] & r.SM_PDI_REPEAT_ACK
    assert e.read(MBX_IN, got, 0) and got[:2] == b"\x07\x07"


def logical_esc(app: App) -> Esc:
    """An ESC in OP with 4 output bytes at OUT (FMMU 0, logical 0) and 2 inputs at IN (FMMU 1, logical 4)."""
    e = esc(app)
    mailboxes_configured(e)
    e.write(
        r.SM0 + 16, r.SYNC_MANAGER.pack(OUT, 4, 0x64, 0, 1, 0) + r.SYNC_MANAGER.pack(IN, 2, 0x20, 0, 1, 0), 0
    )
    fmmus = r.FMMU.pack(0, 4, 0, 7, OUT, 0, 2, 1) + r.FMMU.pack(4, 2, 0, 7, IN, 0, 1, 1)
    e.write(r.FMMU0, fmmus, 0)
    for state in (AlState.PRE_OP, AlState.SAFE_OP, AlState.OP):
        write_u16(e, r.AL_CONTROL, state)
    assert e.al_state is AlState.OP
    return e


def test_logical_read_write_through_the_fmmus_counts_three() -> None:
    app = App()
    e = logical_esc(app)
    e.write_inputs(3, b"\xaa\xbb")
    data = bytearray(b"\x01\x02\x03\x04\x00\x00")
    assert e.logical(0, data, read=True, write=True, clock_ns=5) == 3
    assert data[4:] == b"\xaa\xbb" and app.outputs == [b"\x01\x02\x03\x04"]


def test_the_sm_watchdog_takes_the_slave_to_safe_op() -> None:
    app = App()
    e = logical_esc(app)
    e.logical(0, bytearray(6), read=True, write=True, clock_ns=1_000_000)
    e.poll(50_000_000)
    assert e.al_state is AlState.OP
    e.poll(1_000_000 + e.watchdog_ns + 1)
    assert e.mem[r.AL_STATUS] == AlState.SAFE_OP | r.AL_ERROR
    assert e.al_status_code == AlStatusCode.SYNC_MANAGER_WATCHDOG and app.watchdogs == 1


def test_a_line_addresses_by_position_station_and_broadcast() -> None:
    line = Chain([esc(), esc(), esc()])
    (out,) = line.process([Datagram(Command.BRD, 1, 0, b"\x00\x00")], 0)
    assert out.wkc == 3 and out.data == b"\x11\x00"  # every slave's type, ORed
    (out,) = line.process([Datagram(Command.APWR, 2, (r.STATION_ADDRESS << 16) | 0xFFFF, b"\x02\x10")], 0)
    assert out.wkc == 1 and line.escs[1].station_address == 0x1002  # position -1: the second
    (out,) = line.process([Datagram(Command.FPRD, 3, (r.STATION_ADDRESS << 16) | 0x1002, b"\x00\x00")], 0)
    assert out.wkc == 1 and out.data == b"\x02\x10"
    (out,) = line.process([Datagram(Command.FPRW, 4, (r.STATION_ADDRESS << 16) | 0x1002, b"\x03\x10")], 0)
    assert out.wkc == 3 and out.data == b"\x02\x10" and line.escs[1].station_address == 0x1003


def test_a_cable_pulled_hides_the_slaves_beyond_and_closes_the_port_before() -> None:
    line = Chain([esc(), esc(), esc()])
    line.unplug(2)
    (out,) = line.process([Datagram(Command.BRD, 1, 0, b"\x00\x00")], 0)
    assert out.wkc == 1
    assert struct.unpack_from("<H", line.escs[0].mem, r.DL_STATUS)[0] & 0x0C00 == 0x0400  # port 1 closed
    line.lose_frames(1)
    assert line.process([Datagram(Command.BRD, 2, 0, b"\x00\x00")], 0) is None
    line.replug()
    (out,) = line.process([Datagram(Command.BRD, 3, 0, b"\x00\x00")], 0)
    assert out.wkc == 3
