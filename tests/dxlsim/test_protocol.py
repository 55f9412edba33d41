"""Protocol 2.0 framing against the e-Manual's own example packets (Protocol 2.0 page)."""

from __future__ import annotations

from orccadd.dxlsim.protocol import (
    Instruction,
    PacketReader,
    crc16,
    fast_status_packet,
    instruction_packet,
    status_packet,
    stuff,
    unstuff,
)


def test_crc_of_the_e_manual_ping_packet() -> None:
    # Ping ID 1: FF FF FD 00 01 03 00 01, CRC 19 4E
    assert crc16(bytes.fromhex("FFFFFD0001030001")) == 0x4E19
    assert instruction_packet(1, Instruction.PING) == bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")


def test_status_packets_of_the_e_manual_examples() -> None:
    # ping reply of an XM430-W210 (model 1030, firmware 38); read of Present Position = 166
    assert status_packet(1, 0, bytes.fromhex("06 04 26")) == bytes.fromhex(
        "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"
    )
    assert status_packet(1, 0, bytes.fromhex("A6 00 00 00")) == bytes.fromhex(
        "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0"
    )


def test_instruction_packets_of_the_e_manual_examples() -> None:
    # write 512 to Goal Position(116) of ID 1; sync read of Present Position from IDs 1, 2
    assert instruction_packet(1, Instruction.WRITE, bytes.fromhex("74 00 00 02 00 00")) == bytes.fromhex(
        "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"
    )
    assert instruction_packet(
        0xFE, Instruction.SYNC_READ, bytes.fromhex("84 00 04 00 01 02")
    ) == bytes.fromhex("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA")


def test_fast_sync_read_reply_of_the_e_manual_example() -> None:
    # IDs 3, 7, 4: Present Position 166, 2079, 1023; each part's CRC runs over the packet so far
    parts = [(i, 0, value.to_bytes(4, "little")) for i, value in ((3, 166), (7, 2079), (4, 1023))]
    expected = bytes.fromhex(
        "FF FF FD 00 FE 19 00 55"  # header, broadcast ID, length 25, status
        " 00 03 A6 00 00 00 84 08"  # ID 3: error, id, data, CRC so far
        " 00 07 1F 08 00 00 16 CA"  # ID 7
        " 00 04 FF 03 00 00 D1 9E"  # ID 4: its CRC is the packet's
    )
    assert fast_status_packet(parts) == expected


def test_stuffing_round_trip_and_length() -> None:
    body = bytes.fromhex("03 FF FF FD 00 FF FF FD FD")
    assert stuff(body) == bytes.fromhex("03 FF FF FD FD 00 FF FF FD FD FD")
    assert unstuff(stuff(body)) == body
    packet = instruction_packet(1, Instruction.WRITE, bytes.fromhex("74 00 FF FF FD 00"))
    assert int.from_bytes(packet[5:7], "little") == 1 + 7 + 2  # instruction, stuffed params, CRC
    (parsed,) = PacketReader().feed(packet)
    assert parsed.crc_ok and parsed.params == bytes.fromhex("74 00 FF FF FD 00")
    reply = status_packet(2, 0, bytes.fromhex("FF FF FF FF FD 00 00 00"))
    assert reply[9:-2] == bytes.fromhex("FF FF FF FF FD FD 00 00 00")


def test_reader_takes_chunks_skips_garbage_and_flags_a_bad_crc() -> None:
    reader = PacketReader()
    ping, read = instruction_packet(1, Instruction.PING), instruction_packet(2, Instruction.READ, bytes(4))
    stream = b"\x00\xff\x12" + ping + read[:-1] + bytes((read[-1] ^ 0x40,))
    packets = []
    for i in range(0, len(stream), 3):
        packets += reader.feed(stream[i : i + 3])
    assert [(p.dxl_id, p.instruction, p.crc_ok) for p in packets] == [(1, 1, True), (2, 2, False)]
    assert reader.pending == 0
