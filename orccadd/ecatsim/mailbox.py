"""The EtherCAT mailbox's header and its error reply (ETG.1000.4 5.6, ETG.1000.6 5.6).

Every mailbox message starts with 6 bytes, little-endian: the length of what follows the header
(uint16, bytes), an address (uint16), channel (bits 0-5) and priority (bits 6-7) in one byte, and
the type (bits 0-3) with the counter (bits 4-6) in the last. The counter runs 1..7 and wraps to 1;
0 is sent only right after INIT. A message the slave cannot serve is answered with a mailbox error
reply: type 0, the header then service (uint16, 1) and a detail code (uint16, `ErrorDetail`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

HEADER = struct.Struct("<HHBB")  # length, address, channel and priority, type and counter
ERROR_BODY = struct.Struct("<HH")  # service, detail
ERROR_SERVICE = 0x0001  # the only service of a mailbox error reply
COUNTER_MAX = 7


class MailboxType(IntEnum):
    """The protocol a mailbox message carries (header byte 5, bits 0-3)."""

    ERROR = 0
    AOE = 1
    EOE = 2
    COE = 3
    FOE = 4
    SOE = 5
    VOE = 15


class ErrorDetail(IntEnum):
    """A mailbox error reply's detail code (ETG.1000.4, the mailbox error reply)."""

    SYNTAX = 0x0001  # the 6-byte mailbox header is wrong
    UNSUPPORTED_PROTOCOL = 0x0002  # a type the slave does not serve
    INVALID_CHANNEL = 0x0003
    SERVICE_NOT_SUPPORTED = 0x0004  # a service of the protocol the slave does not serve
    INVALID_HEADER = 0x0005  # the protocol's own header (CoE's) is wrong
    SIZE_TOO_SHORT = 0x0006  # less data than the protocol's header and service need
    NO_MORE_MEMORY = 0x0007
    INVALID_SIZE = 0x0008  # the length does not fit the mailbox's buffer


@dataclass(frozen=True)
class MailboxHeader:
    """The 6-byte header; `length` in bytes after it."""

    length: int
    address: int
    channel: int
    priority: int
    type: int
    counter: int

    @staticmethod
    def parse(data: bytes) -> MailboxHeader:
        """The header at the start of `data` (at least `HEADER.size` bytes)."""
        length, address, channel_priority, type_counter = HEADER.unpack_from(data)
        return MailboxHeader(
            length,
            address,
            channel_priority & 0x3F,
            channel_priority >> 6,
            type_counter & 0x0F,
            type_counter >> 4 & 0x07,
        )


def next_counter(counter: int) -> int:
    """The counter after `counter`: 1..7, then 1 again (0 only right after INIT)."""
    return 1 if counter >= COUNTER_MAX else counter + 1


def message(kind: MailboxType, counter: int, body: bytes) -> bytes:
    """A mailbox message: the header (address 0, channel 0, priority 0) then `body`, unpadded."""
    return HEADER.pack(len(body), 0, 0, kind | counter << 4) + body


def error_reply(detail: ErrorDetail, counter: int) -> bytes:
    """A mailbox error reply (type 0) with `detail`, unpadded (10 bytes)."""
    return message(MailboxType.ERROR, counter, ERROR_BODY.pack(ERROR_SERVICE, detail))
