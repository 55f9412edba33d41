"""Packet lengths of Protocol 2.0 and their time on the line (e-Manual, Protocol 2.0).

Every packet is `FF FF FD 00 | ID | LEN_L LEN_H | INST | [ERR] | params | CRC_L CRC_H`: 10
bytes around an instruction's parameters, 11 around a status packet's. A byte is 10 bit times
on the line (start, 8 data, stop). Byte stuffing (a rare `FF FF FD` in the data) is ignored.

- Fast Sync Read: the instruction (address, length, one ID per servo) and ONE status packet for
  all servos: 8 bytes of header and instruction, then per servo error, ID, data and CRC;
- Sync Read: the same instruction, then one status packet per servo;
- Sync Write: address, length, then ID and data per servo; no status packet.

Each answering servo first waits its Return Delay Time(9) (the backend sets it to 0).
"""

from __future__ import annotations

BITS_PER_BYTE = 10
INSTRUCTION_OVERHEAD = 10
STATUS_OVERHEAD = 11


def byte_time_s(baud_bit_s: int) -> float:
    return BITS_PER_BYTE / baud_bit_s


def sync_read_request_bytes(n_servos: int) -> int:
    return INSTRUCTION_OVERHEAD + 4 + n_servos


def fast_sync_read_reply_bytes(n_servos: int, length: int) -> int:
    return 8 + n_servos * (length + 4)


def sync_read_reply_bytes(n_servos: int, length: int) -> int:
    return n_servos * (STATUS_OVERHEAD + length)


def sync_write_bytes(n_servos: int, length: int) -> int:
    return INSTRUCTION_OVERHEAD + 4 + n_servos * (1 + length)


def read_time_s(
    n_servos: int, length: int, baud_bit_s: int, return_delay_s: float = 0.0, fast: bool = True
) -> float:
    """One (fast) sync read of `length` bytes from `n_servos`: request, replies, return delays."""
    if fast:
        wire = sync_read_request_bytes(n_servos) + fast_sync_read_reply_bytes(n_servos, length)
        delays = return_delay_s
    else:
        wire = sync_read_request_bytes(n_servos) + sync_read_reply_bytes(n_servos, length)
        delays = n_servos * return_delay_s
    return wire * byte_time_s(baud_bit_s) + delays


def write_time_s(n_servos: int, length: int, baud_bit_s: int) -> float:
    """One sync write of `length` bytes to `n_servos`."""
    return sync_write_bytes(n_servos, length) * byte_time_s(baud_bit_s)
