"""The master's batching socketcand client (python-can's, with a tick's frames in one write) and
one bus of the master, against the userspace hub and a stock python-can client."""

from __future__ import annotations

import logging
import select
import time
from collections.abc import Iterator

import can
import pytest

from orccadd.drivers.canopen.port import BatchingSocketcandBus, BusPort
from orccadd.drivers.canopen.settings import Bus
from orccadd.vcan.hub import HOLD_OFF_S
from orccadd.vcan.process import HOST, HubProcess
from tests.canopen_rig import receive

logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)


@pytest.fixture
def hub() -> Iterator[HubProcess]:
    with HubProcess() as h:
        yield h


@pytest.fixture
def buses(hub: HubProcess) -> Iterator[tuple[BatchingSocketcandBus, can.BusABC]]:
    ours = BatchingSocketcandBus("can0", HOST, hub.port, tcp_tune=True)
    stock = can.Bus(**hub.bus_kwargs("can0"))
    time.sleep(2 * HOLD_OFF_S)
    try:
        yield ours, stock
    finally:
        ours.shutdown()
        stock.shutdown()


def frames(n: int) -> list[can.Message]:
    return [
        can.Message(
            arbitration_id=0x201 + k, data=bytes([0x0F, 0, k, 0, 0, 0, 0x10, 0]), is_extended_id=False
        )
        for k in range(n)
    ] + [can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)]  # RPDOs, then SYNC


def test_queued_frames_leave_on_flush_in_order(buses: tuple[BatchingSocketcandBus, can.BusABC]) -> None:
    ours, stock = buses
    tick = frames(6)
    for f in tick:
        ours.queue(f)
    assert stock.recv(0.2) is None  # held until the tick's end
    ours.flush()
    got = receive(stock, len(tick))
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
        (f.arbitration_id, bytes(f.data)) for f in tick
    ]
    ours.flush()  # nothing queued: nothing sent
    assert stock.recv(0.2) is None


def test_send_stays_immediate_and_receive_is_python_cans(
    buses: tuple[BatchingSocketcandBus, can.BusABC],
) -> None:
    ours, stock = buses
    ours.send(can.Message(arbitration_id=0x77F, data=b"\x05", is_extended_id=False))  # a periodic task's
    (m,) = receive(stock, 1)
    assert (m.arbitration_id, bytes(m.data)) == (0x77F, b"\x05")
    stock.send(can.Message(arbitration_id=0x181, data=b"\x27\x06\x01\x02\x03\x04", is_extended_id=False))
    readable, _, _ = select.select([ours.fileno()], [], [], 5.0)  # what a tick waiting for TPDOs uses
    assert readable
    (m,) = receive(ours, 1)
    assert (m.arbitration_id, bytes(m.data)) == (0x181, b"\x27\x06\x01\x02\x03\x04") and m.timestamp > 0


def test_a_port_whose_bus_died_reports_it_naming_the_bus(hub: HubProcess) -> None:
    port = BusPort(Bus("socketcand", "can1", HOST, hub.port, 1_000_000, (0,)))
    port.open()
    try:
        hub.kill()
        end = time.monotonic() + 5.0
        while not port.error and time.monotonic() < end:  # the first writes may still be buffered
            for f in frames(3):
                port.queue(f)
            port.flush()
            time.sleep(0.01)
        assert port.error.startswith(f"CAN bus can1 (socketcand {HOST}:{hub.port}): ")
    finally:
        port.close([])
    assert port.bus is None
