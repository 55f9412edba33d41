"""Packet lengths and wire time, cross-checked against packets built by the SDK and by the
simulator (two independent routes to the same bytes)."""

from __future__ import annotations

import pytest
from dynamixel_sdk import GroupSyncWrite, PacketHandler

from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel import wire
from orccadd.dxlsim.link import wire_time_s
from orccadd.dxlsim.protocol import Instruction, fast_status_packet, instruction_packet, status_packet


@pytest.mark.parametrize("n", [1, 3, 6, 12])
def test_lengths_match_the_simulators_packets(n: int) -> None:
    ids = bytes(range(1, n + 1))
    request = instruction_packet(0xFE, Instruction.FAST_SYNC_READ, bytes((126, 0, 10, 0)) + ids)
    assert len(request) == wire.sync_read_request_bytes(n)
    reply = fast_status_packet([(i, 0, bytes(10)) for i in ids])
    assert len(reply) == wire.fast_sync_read_reply_bytes(n, 10)
    assert n * len(status_packet(1, 0, bytes(10))) == wire.sync_read_reply_bytes(n, 10)
    write = instruction_packet(0xFE, Instruction.SYNC_WRITE, bytes((116, 0, 4, 0)) + bytes(5 * n))
    assert len(write) == wire.sync_write_bytes(n, 4)


class _Port:
    """Records what the SDK writes."""

    is_using = False
    sent: list[int]

    def clearPort(self) -> None:  # noqa: N802
        pass

    def writePort(self, packet: list[int]) -> int:  # noqa: N802
        self.sent = list(packet)
        return len(packet)


def test_the_sync_write_length_matches_the_sdks_packet() -> None:
    port = _Port()
    group = GroupSyncWrite(port, PacketHandler(2.0), T.GOAL_POSITION.address, 4)
    for i in range(1, 7):
        group.addParam(i, [0x10, 0, 0, 0])
    group.txPacket()
    assert len(port.sent) == wire.sync_write_bytes(6, 4)


def test_wire_time_is_10_bits_a_byte_plus_return_delays() -> None:
    # six servos at 4 Mbit/s: 20 + 92 bytes read, 44 written
    assert wire.read_time_s(6, 10, 4_000_000) == pytest.approx(112 * 10 / 4e6)
    assert wire.write_time_s(6, 4, 4_000_000) == pytest.approx(44 * 10 / 4e6)
    assert wire.read_time_s(6, 10, 1_000_000) == pytest.approx(4 * wire.read_time_s(6, 10, 4_000_000))
    assert wire.byte_time_s(57_600) == wire_time_s(1, 57_600)  # the simulator's line agrees
    # plain sync read: six status packets, each after its servo's return delay
    plain = wire.read_time_s(6, 10, 1_000_000, return_delay_s=500e-6, fast=False)
    assert plain == pytest.approx((20 + 6 * 21) * 10e-6 + 6 * 500e-6)
    assert wire.read_time_s(6, 10, 1_000_000, return_delay_s=500e-6) == pytest.approx(112 * 10e-6 + 500e-6)
