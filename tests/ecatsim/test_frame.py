"""EtherCAT frames: one captured from stock pysoem (SOEM) read as SOEM wrote it, frames of
several datagrams through encode and parse unchanged, and malformed bytes refused naming where."""

from __future__ import annotations

import pytest

from orccadd.ecatsim.frame import Command, Datagram, EthernetFrame, FrameError, encode, parse

# the first frame pysoem 1.1.13's `Master.config_init()` sent on a veth link (captured with a raw
# socket on its peer): broadcast, source 01:01:01:01:01:01, one BWR of one byte to register 0x0103
# (Ethernet: destination, source, type; EtherCAT header; datagram: command and index, address,
# length and flags, IRQ, data, working counter)
SOEM_FIRST = bytes.fromhex("ffffffffffff 010101010101 88a4 0d10 0801 00000301 0100 0000 00 0000")


def test_the_frame_soem_sends_first_reads_as_it_wrote_it() -> None:
    frame = EthernetFrame.parse(SOEM_FIRST)
    assert frame.destination == b"\xff" * 6 and frame.source == b"\x01" * 6
    (d,) = frame.datagrams
    assert d.command is Command.BWR and d.index == 1 and d.adp == 0 and d.ado == 0x0103
    assert d.data == b"\x00" and d.wkc == 0 and not d.circulated


def test_several_datagrams_go_through_encode_and_parse_unchanged() -> None:
    datagrams = [
        Datagram(Command.APRD, 3, (0x0130 << 16) | 0xFFFF, bytes(2)),
        Datagram(Command.LRW, 4, 0x0001_0000, bytes(range(24)), wkc=3),
        Datagram(Command.FPWR, 5, (0x0120 << 16) | 0x1001, b"\x02\x00", irq=7, circulated=True),
    ]
    assert parse(encode(datagrams)) == datagrams
    frame = EthernetFrame(b"\xff" * 6, b"\x02" * 6, datagrams)
    wire = frame.encode()
    assert EthernetFrame.parse(wire) == frame  # padding after the datagrams ignored
    short = EthernetFrame(b"\xff" * 6, b"\x02" * 6, datagrams[:1]).encode()
    assert len(short) == 14 + 46  # padded to Ethernet's minimum


def test_an_answered_datagram_keeps_its_header_with_new_data_and_counter() -> None:
    d = Datagram(Command.BRD, 9, 0x0130 << 16, bytes(2))
    a = d.answered(b"\x08\x00", 2)
    assert (a.command, a.index, a.address, a.data, a.wkc) == (Command.BRD, 9, 0x0130 << 16, b"\x08\x00", 2)


@pytest.mark.parametrize(
    ("wire", "says"),
    [
        (b"\x01", "shorter than its 2-byte header"),
        (bytes.fromhex("0d20") + bytes(13), "type 2"),
        (bytes.fromhex("0d10") + bytes(5), "says 13 bytes"),
        (bytes.fromhex("0c10") + bytes.fromhex("08010000030101000000") + bytes(2), "past the datagrams"),
        (bytes.fromhex("0d10") + bytes.fromhex("0f010000030101000000") + bytes(3), "no command 15"),
        (bytes.fromhex("0f10") + bytes.fromhex("08010000030101000000") + bytes(5), "2 bytes after the last"),
    ],
)
def test_malformed_frames_are_refused_naming_what_is_wrong(wire: bytes, says: str) -> None:
    with pytest.raises(FrameError, match=says):
        parse(wire)


def test_an_ethernet_frame_of_another_type_is_refused() -> None:
    with pytest.raises(FrameError, match="0x0800"):
        EthernetFrame.parse(bytes(12) + b"\x08\x00" + bytes(46))
