"""The drive simulator's queued socketcand client against the hub and stock python-can."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import can
import pytest

from orccadd.drivesim.socketcand import QueuedSocketcandBus
from orccadd.vcan.hub import HOLD_OFF_S
from orccadd.vcan.process import HOST, HubProcess
from tests.canopen_rig import receive

logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)


@pytest.fixture
def buses() -> Iterator[tuple[QueuedSocketcandBus, can.BusABC]]:
    with HubProcess() as h:
        ours = QueuedSocketcandBus("can0", HOST, h.port)
        stock = can.Bus(**h.bus_kwargs("can0"))
        time.sleep(2 * HOLD_OFF_S)
        try:
            yield ours, stock
        finally:
            ours.shutdown()
            stock.shutdown()


def test_queued_frames_leave_on_send_queued_in_order(buses: tuple[QueuedSocketcandBus, can.BusABC]) -> None:
    ours, stock = buses
    frames = [
        can.Message(arbitration_id=0x181 + k, data=bytes([k, 0xFF, 0x10]), is_extended_id=False)
        for k in range(6)
    ]
    frames.append(can.Message(arbitration_id=0x1ABCDE, data=b"", is_extended_id=True))
    for f in frames:
        ours.send(f)
    assert stock.recv(0.2) is None  # queued, like a CAN controller's transmit mailboxes
    ours.send_queued()
    got = receive(stock, len(frames))
    assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in got] == [
        (f.arbitration_id, f.is_extended_id, bytes(f.data)) for f in frames
    ]


def test_frames_from_stock_python_can_arrive_with_the_hub_timestamp(
    buses: tuple[QueuedSocketcandBus, can.BusABC],
) -> None:
    ours, stock = buses
    for k in range(50):
        stock.send(can.Message(arbitration_id=0x201, data=k.to_bytes(8, "little"), is_extended_id=False))
    got = receive(ours, 50)
    assert [int.from_bytes(m.data, "little") for m in got] == list(range(50))
    assert all(abs(time.time() - m.timestamp) < 10.0 for m in got)  # wall-clock stamps, seconds
