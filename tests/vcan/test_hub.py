"""The userspace virtual CAN hub, driven by stock python-can's socketcand client."""

from __future__ import annotations

import logging
import re
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from orccadd.vcan.hub import HOLD_OFF_S
from orccadd.vcan.process import HOST, HubProcess

# python-can warns on every TCP read that ends mid-message; it then waits for the rest
logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)


@pytest.fixture
def hub() -> Iterator[HubProcess]:
    with HubProcess() as h:
        yield h


def connect(h: HubProcess, n: int, channel: str = "can0") -> list[can.BusABC]:
    buses = [can.Bus(**h.bus_kwargs(channel)) for _ in range(n)]
    time.sleep(2 * HOLD_OFF_S)  # frames reach a new client after its short hold-off
    return buses


def drain(bus: can.BusABC, n: int, timeout_s: float = 10.0) -> list[can.Message]:
    got: list[can.Message] = []
    end = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < end:
        m = bus.recv(0.5)
        if m is not None:
            got.append(m)
    return got


def shutdown(buses: list[can.BusABC]) -> None:
    for b in buses:
        b.shutdown()


def test_every_other_client_gets_every_frame_in_order_and_the_sender_none(hub: HubProcess) -> None:
    a, b, c = buses = connect(hub, 3)
    try:
        n = 10_000
        for i in range(n):
            a.send(
                can.Message(
                    arbitration_id=0x180 + i % 127, data=i.to_bytes(4, "little"), is_extended_id=False
                )
            )
        for rx in (b, c):
            got = drain(rx, n)
            assert len(got) == n
            assert [int.from_bytes(m.data, "little") for m in got] == list(range(n))
            assert all(m.arbitration_id == 0x180 + i % 127 for i, m in enumerate(got))
        assert a.recv(0.3) is None  # no echo
    finally:
        shutdown(buses)


@pytest.mark.parametrize(
    "msg",
    [
        can.Message(arbitration_id=0x000, data=b"", is_extended_id=False),
        can.Message(arbitration_id=0x7FF, data=bytes(range(8)), is_extended_id=False),
        can.Message(arbitration_id=0x1ABCDEF0, data=b"\x00\xff", is_extended_id=True),
    ],
    ids=["empty", "eight-bytes", "extended"],
)
def test_frames_arrive_unchanged(hub: HubProcess, msg: can.Message) -> None:
    a, b = buses = connect(hub, 2)
    try:
        a.send(msg)
        (got,) = drain(b, 1)
        assert (got.arbitration_id, got.is_extended_id, bytes(got.data)) == (
            msg.arbitration_id,
            msg.is_extended_id,
            bytes(msg.data),
        )
    finally:
        shutdown(buses)


def test_channels_are_separate_buses(hub: HubProcess) -> None:
    a0, b0 = connect(hub, 2, "can0")
    a1, b1 = connect(hub, 2, "can1")
    try:
        a0.send(can.Message(arbitration_id=0x10, data=b"\x00"))
        a1.send(can.Message(arbitration_id=0x11, data=b"\x01"))
        assert [m.arbitration_id for m in drain(b0, 2, 1.0)] == [0x10]
        assert [m.arbitration_id for m in drain(b1, 2, 1.0)] == [0x11]
    finally:
        shutdown([a0, b0, a1, b1])


def test_bad_input_is_ignored_and_the_hub_serves_on(hub: HubProcess) -> None:
    raw = socket.create_connection((HOST, hub.port))
    try:
        assert raw.recv(64) == b"< hi >"
        raw.sendall(b"< open can0 >")
        assert raw.recv(64) == b"< ok >"
        raw.sendall(b"< rawmode >")
        assert raw.recv(64) == b"< ok >"
        raw.sendall(b"< send 12 >< send 1234 1 0 >< send 123 9 1 2 3 4 5 6 7 8 9 >< bogus >garbage")
        a, b = buses = connect(hub, 2)
        try:
            a.send(can.Message(arbitration_id=0x123, data=b"\x42", is_extended_id=False))
            assert [(m.arbitration_id, bytes(m.data)) for m in drain(b, 1)] == [(0x123, b"\x42")]
            raw.sendall(b"x" * 300)  # a "line" with no end: that client is dropped, nobody else
            raw.settimeout(5)
            received = b""
            while chunk := raw.recv(4096):  # b"": the hub closed the connection (a timeout fails)
                received += chunk
            # the raw client got a's frame, unchanged, and nothing else (no echo of its own sends)
            assert re.fullmatch(rb"< frame 123 \d+\.\d{6} 42 >", received), received
            a.send(can.Message(arbitration_id=0x124, data=b"\x43", is_extended_id=False))
            assert [(m.arbitration_id, bytes(m.data)) for m in drain(b, 1)] == [(0x124, b"\x43")]
        finally:
            shutdown(buses)
    finally:
        raw.close()
    assert hub.proc.poll() is None


def test_a_client_that_stops_reading_is_disconnected_not_the_others() -> None:
    with HubProcess("--max-backlog-bytes", "65536") as h:
        sender, reader = buses = connect(h, 2)
        silent = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        silent.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        silent.connect((HOST, h.port))
        silent.recv(64)
        silent.sendall(b"< open can0 >")
        silent.recv(64)
        silent.sendall(b"< rawmode >")
        silent.recv(64)
        try:
            n = 30_000  # ~1.1 MB: more than the hub's kernel queue to the silent client plus the limit
            got: list[can.Message] = []
            rx = threading.Thread(target=lambda: got.extend(drain(reader, n, 40.0)))
            rx.start()
            for i in range(n):  # about the frame rate of a busy 1 Mbit/s bus
                sender.send(can.Message(arbitration_id=0x200, data=i.to_bytes(2, "little")))
                if i % 100 == 99:
                    time.sleep(0.02)
            rx.join()
            assert len(got) == n
            assert [int.from_bytes(m.data, "little") for m in got] == list(range(n))
        finally:
            shutdown(buses)
            silent.close()
        h.stop()
        assert "not reading" in h.stderr_text()


def test_reports_its_port_and_stops_on_sigterm(tmp_path: Path) -> None:
    port_file = tmp_path / "port"
    h = HubProcess("--port-file", str(port_file))
    try:
        assert int(port_file.read_text()) == h.port
    finally:
        assert h.stop() == 0


def test_stops_on_sigterm_with_clients_connected_without_a_traceback() -> None:
    h = HubProcess()
    buses = connect(h, 2)
    try:
        buses[0].send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
        drain(buses[1], 1)
        assert h.stop() == 0
        assert "Traceback" not in h.stderr_text() and "CancelledError" not in h.stderr_text(), h.stderr_text()
    finally:
        shutdown(buses)
        h.stop()
