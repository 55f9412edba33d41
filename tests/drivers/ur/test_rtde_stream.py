"""Our blocking RTDE output stream (`drivers.ur.rtde_stream`): against the UR controller
simulator beside stock ur_rtde, and against a hand-made controller for what a real one may send
(text messages, a package of another recipe, a closed connection, a malformed header)."""

from __future__ import annotations

import socket
import struct
import threading
from collections.abc import Iterator

import numpy as np
import pytest

from orccadd.drivers.ur.rtde_stream import EXPECTED_TYPES, FORMATS, RECIPE, RtdeError, RtdeStream
from orccadd.ursim.process import UrSimProcess
from tests.conftest import ROOT

CONFIG = ROOT / "configs/robots/ur5e-rtde-sim.toml"
pytestmark = pytest.mark.timeout(120, method="thread")


def test_every_controller_cycle_is_read_in_order_and_agrees_with_stock_ur_rtde() -> None:
    import rtde_receive

    with UrSimProcess(CONFIG, "--boot", "running"):
        stream = RtdeStream("127.0.0.1", 500.0)
        try:
            stamps = [stream.read().stamp for _ in range(200)]
            pkg = stream.read()
            stock = rtde_receive.RTDEReceiveInterface("127.0.0.1", 500.0)
            q_stock = stock.getActualQ()
            stock.disconnect()
        finally:
            stream.close()
    steps = np.round(np.diff(stamps) / 0.002)
    assert steps.min() >= 1 and np.median(steps) == 1  # one package per cycle, none twice
    assert pkg.robot_mode == 7 and pkg.script_running is False  # RUNNING, no program yet
    np.testing.assert_allclose(pkg.q_rad, q_stock, atol=1e-3)  # the arm at rest: the same q
    assert len(pkg.tcp_force) == 6 and pkg.runtime_state == 1  # STOPPED: no program


def test_a_frequency_the_controller_refuses_is_an_error_naming_it() -> None:
    with (
        UrSimProcess(CONFIG, "--boot", "running") as _sim,
        pytest.raises(RtdeError, match="refused at 1000 Hz"),
    ):
        RtdeStream("127.0.0.1", 1000.0)


class FakeController:
    """A one-connection RTDE server on 127.0.0.1: accepts the setup, then sends what the test says."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.conn: socket.socket | None = None
        self.ready = threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    @staticmethod
    def package(kind: str, payload: bytes) -> bytes:
        return struct.pack(">HB", 3 + len(payload), ord(kind)) + payload

    def _serve(self) -> None:
        conn, _ = self.server.accept()
        self.conn = conn
        for kind, reply in (
            ("V", b"\x01"),
            ("O", b"\x05" + ",".join(EXPECTED_TYPES).encode()),
            ("S", b"\x01"),
        ):
            head = conn.recv(3, socket.MSG_WAITALL)
            size, got = struct.unpack(">HB", head)
            conn.recv(size - 3, socket.MSG_WAITALL) if size > 3 else b""
            assert chr(got) == kind
            if kind == "O":  # a text message before the answer, as a controller may send
                conn.sendall(self.package("M", b"\x00\x05hello"))
            conn.sendall(self.package(kind, reply))
        self.ready.set()

    def data(self, recipe: int, stamp: float) -> bytes:
        fmt = ">B" + "".join(FORMATS[t] for t in EXPECTED_TYPES)
        values: list[float | int] = [
            recipe,
            stamp,
            *[0.1] * 6,
            *[0.0] * 6,
            *[1.0] * 6,
            7,
            1,
            1,
            2,
            *[0.0] * 6,
            0.5,
            3,
        ]
        return self.package("U", struct.pack(fmt, *values))

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.server.close()


@pytest.fixture
def fake() -> Iterator[FakeController]:
    f = FakeController()
    yield f
    f.close()


def test_packages_of_another_recipe_and_text_messages_are_skipped(fake: FakeController) -> None:
    stream = RtdeStream("127.0.0.1", 500.0, port=fake.port)
    assert fake.ready.wait(5) and fake.conn is not None
    fake.conn.sendall(fake.data(4, 1.0) + fake.package("M", b"\x00\x02hi") + fake.data(5, 2.0)[:20])
    fake.conn.sendall(fake.data(5, 2.0)[20:])  # split across reads
    pkg = stream.read()
    assert pkg.stamp == 2.0 and pkg.q_rad == (0.1,) * 6 and pkg.script_running  # bit 1: program running
    assert pkg.speed_scaling == 0.5 and pkg.digital_inputs == 3 and len(RECIPE) == len(EXPECTED_TYPES)
    stream.close()


def test_a_closed_connection_or_a_malformed_package_ends_the_read_with_an_error(fake: FakeController) -> None:
    stream = RtdeStream("127.0.0.1", 500.0, port=fake.port)
    assert fake.ready.wait(5) and fake.conn is not None
    fake.conn.sendall(struct.pack(">HB", 1, ord("U")))
    with pytest.raises(RtdeError, match="malformed package"):
        stream.read()
    stream.close()


def test_closing_the_stream_from_another_thread_ends_a_blocked_read(fake: FakeController) -> None:
    stream = RtdeStream("127.0.0.1", 500.0, port=fake.port)
    assert fake.ready.wait(5)
    errors: list[Exception] = []

    def reader() -> None:
        try:
            stream.read()
        except RtdeError as e:
            errors.append(e)

    t = threading.Thread(target=reader)
    t.start()
    stream.close()
    t.join(5)
    assert not t.is_alive() and errors


def test_nobody_listening_is_an_error_naming_where() -> None:
    port = socket.create_server(("127.0.0.1", 0))
    free = port.getsockname()[1]
    port.close()
    with pytest.raises(RtdeError, match=f"RTDE at 127.0.0.1:{free}"):
        RtdeStream("127.0.0.1", 500.0, port=free)
