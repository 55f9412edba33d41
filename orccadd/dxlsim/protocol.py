"""DYNAMIXEL Protocol 2.0 on the wire: CRC-16, byte stuffing, instruction and status packets.

From the ROBOTIS e-Manual, "Protocol 2.0" (emanual.robotis.com/docs/en/dxl/protocol2/):

    FF FF FD 00 | ID | LEN_L LEN_H | INST | [ERR] | params … | CRC_L CRC_H

`LEN` counts the instruction, the error byte (status packets), the parameters after byte
stuffing, and the CRC. Byte stuffing: inside the instruction and parameters, every
`FF FF FD` becomes `FF FF FD FD`, so a header never appears inside a packet. The CRC is
CRC-16 with polynomial 0x8005, initial value 0, no reflection ("CRC-16/BUYPASS"), computed over
the whole stuffed packet from the first header byte to the last parameter.

The status packet of Fast Sync Read / Fast Bulk Read is one packet for every servo asked: ID
0xFE, then per servo `error, id, data…, crc` where each servo's CRC is the CRC of the packet so
far (the last servo's is the packet's own CRC); it is never stuffed (e-Manual, Fast Sync Read).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC  # 253 (0xFD) and 255 (0xFF) are never IDs: they would look like a header
MAX_LENGTH = 1024  # longest LEN this simulator accepts (a real servo's buffer is of this order)
_STUFF_FROM = b"\xff\xff\xfd"
_STUFF_TO = b"\xff\xff\xfd\xfd"
POLY = 0x8005


class Instruction(IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class Error(IntEnum):
    """The error number of a status packet (bits 0-6 of its error byte)."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


ALERT = 0x80  # error byte bit 7: a hardware error is latched (Hardware Error Status, address 70)


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = (crc << 1) ^ POLY if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_TABLE = _crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 (poly 0x8005, MSB first) of `data`, continuing from `crc`."""
    table = _TABLE
    for b in data:
        crc = ((crc << 8) ^ table[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Byte stuffing of an instruction or status body (instruction through parameters)."""
    return body.replace(_STUFF_FROM, _STUFF_TO)


def unstuff(body: bytes) -> bytes:
    """The inverse of `stuff`."""
    return body.replace(_STUFF_TO, _STUFF_FROM)


def _frame(dxl_id: int, body: bytes) -> bytes:
    """Header, ID, length and CRC around an already stuffed body."""
    head = HEADER + bytes((dxl_id,)) + (len(body) + 2).to_bytes(2, "little")
    packet = head + body
    return packet + crc16(packet).to_bytes(2, "little")


def instruction_packet(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete instruction packet (what a controller sends)."""
    return _frame(dxl_id, stuff(bytes((instruction,)) + params))


def status_packet(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A complete status packet: instruction 0x55, the error byte, then `params`."""
    return _frame(dxl_id, stuff(bytes((Instruction.STATUS, error)) + params))


def fast_status_packet(parts: Sequence[tuple[int, int, bytes]]) -> bytes:
    """The one status packet of a Fast Sync/Bulk Read: `parts` are (id, error, data) in the
    order asked. Not stuffed; each part ends with the CRC of everything before it."""
    length = 1 + sum(len(data) + 4 for _, _, data in parts)  # +2 bytes id/error, +2 CRC each
    packet = bytearray(HEADER + bytes((BROADCAST_ID,)) + length.to_bytes(2, "little"))
    packet.append(Instruction.STATUS)
    crc = crc16(packet)
    for dxl_id, error, data in parts:
        part = bytes((error, dxl_id)) + data
        packet += part
        crc = crc16(part, crc)
        crc_bytes = crc.to_bytes(2, "little")
        packet += crc_bytes
        crc = crc16(crc_bytes, crc)
    return bytes(packet)


@dataclass(frozen=True)
class Packet:
    """An instruction packet as received: parameters unstuffed; `crc_ok` False if damaged."""

    dxl_id: int
    instruction: int
    params: bytes
    crc_ok: bool
    wire_bytes: int  # its length on the wire, stuffing included


class PacketReader:
    """Finds instruction packets in a byte stream (the servos' side of the bus).

    Bytes before a header are dropped, as is a header whose reserved byte or length cannot be a
    packet's. A packet's bytes may arrive in any number of chunks; `discard_partial` drops an
    unfinished one (a servo's receive timeout)."""

    def __init__(self) -> None:
        self._buf = bytearray()

    @property
    def pending(self) -> int:
        """Bytes held that do not yet make a packet."""
        return len(self._buf)

    def discard_partial(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes) -> list[Packet]:
        """Take `data`; the packets it completes, in order."""
        buf = self._buf
        buf += data
        out: list[Packet] = []
        while True:
            start = buf.find(HEADER[:3])
            if start < 0:
                del buf[: max(0, len(buf) - 2)]  # keep a possible header's first bytes
                return out
            del buf[:start]
            if len(buf) < 7:
                return out
            length = int.from_bytes(buf[5:7], "little")
            if buf[3] != 0x00 or buf[4] in (0xFD, 0xFF) or not 3 <= length <= MAX_LENGTH:
                del buf[0]
                continue
            total = 7 + length
            if len(buf) < total:
                return out
            raw = bytes(buf[:total])
            del buf[:total]
            crc_ok = crc16(raw[:-2]) == int.from_bytes(raw[-2:], "little")
            body = unstuff(raw[7:-2])
            out.append(Packet(raw[4], body[0], body[1:], crc_ok, total))
