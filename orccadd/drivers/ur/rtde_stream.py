"""The controller's RTDE output stream read by a blocking socket read: the tick's clock.

ur_rtde's receive interface offers no wait: its thread polls the socket every 100 µs and its
getters are polled in turn, so a package is seen up to two polls late. UR's own clients read the
stream with a blocking read, and so does this one: one RTDE connection (protocol version 2) with
one output recipe, its packages read as the kernel hands them over. It lives in the link process
(`link_server`) beside ur_rtde's interfaces, which keep the control script and the slow reads.

The protocol, from UR's RTDE guide: every package is `uint16 size` (header included), `uint8
type`, payload, big-endian. 'V' request protocol version (uint16 2 → uint8 accepted); 'O' setup
outputs (double frequency + comma-separated names → uint8 recipe id, 0 when refused, then
comma-separated types, NOT_FOUND for an unknown name); 'S' start (→ uint8 accepted); 'U' data
package (uint8 recipe id, then the recipe's values in its order); 'M' a text message from the
controller (skipped here).
"""

from __future__ import annotations

import contextlib
import socket
import struct
import time
from dataclasses import dataclass

from orccadd.drivers.ur.controller import ROBOT_PROGRAM_RUNNING, Condition, condition

PORT = 30004
PROTOCOL_VERSION = 2
REQUEST_PROTOCOL_VERSION, SETUP_OUTPUTS, START, PAUSE = ord("V"), ord("O"), ord("S"), ord("P")
DATA_PACKAGE, TEXT_MESSAGE = ord("U"), ord("M")
HEADER = struct.Struct(">HB")
# each RTDE type's wire format
FORMATS = {
    "BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d",
    "VECTOR3D": "3d", "VECTOR6D": "6d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I",
}  # fmt: skip
# what the tick needs, in `StreamState`'s order
RECIPE = (
    "timestamp", "actual_q", "actual_qd", "target_moment", "robot_mode", "safety_mode",
    "runtime_state", "robot_status_bits", "actual_TCP_force", "speed_scaling", "actual_digital_input_bits",
)  # fmt: skip
EXPECTED_TYPES = (
    "DOUBLE", "VECTOR6D", "VECTOR6D", "VECTOR6D", "INT32", "INT32",
    "UINT32", "UINT32", "VECTOR6D", "DOUBLE", "UINT64",
)  # fmt: skip


class RtdeError(Exception):
    """The controller refused the setup, or the connection broke (the words say which)."""


@dataclass(frozen=True, slots=True)
class StreamState:
    """One output package of `RECIPE` as the tick uses it (sent by the link process as it is)."""

    stamp: float  # the controller's timestamp, s
    arrival_ns: int  # CLOCK_MONOTONIC when the link process's read returned it
    connected: bool  # the stream and ur_rtde's control interface both connected
    q_rad: tuple[float, ...]
    dq_rad_s: tuple[float, ...]
    target_moment_nm: tuple[float, ...]
    robot_mode: int
    safety_mode: int
    runtime_state: int
    script_running: bool
    tcp_force: tuple[float, ...] = ()  # actual_TCP_force: N and N·m, base frame
    speed_scaling: float = 1.0  # the speed slider's fraction times the controller's own scaling
    digital_inputs: int = 0  # actual_digital_input_bits: standard 0-7, configurable 8-15, tool 16-17

    @classmethod
    def lost(cls, arrival_ns: int) -> StreamState:
        """What the link process sends when the stream breaks."""
        return cls(-1.0, arrival_ns, False, (), (), (), 0, 0, 0, False)

    def condition(self) -> Condition | None:
        """What stops the arm in this package (None: it may move)."""
        return condition(self.robot_mode, self.safety_mode, self.runtime_state, self.script_running)


class RtdeStream:
    """One RTDE output stream at `frequency_hz` from `host`; `read` blocks for the next package."""

    def __init__(self, host: str, frequency_hz: float, *, port: int = PORT, timeout_s: float = 2.0) -> None:
        self.where = f"RTDE at {host}:{port}"
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as e:
            raise RtdeError(f"{self.where}: {e}") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._buf = bytearray()
        try:
            self._setup(frequency_hz)
        except BaseException:
            self.close()
            raise

    def _setup(self, frequency_hz: float) -> None:
        reply = self._request(REQUEST_PROTOCOL_VERSION, struct.pack(">H", PROTOCOL_VERSION))
        if not reply or not reply[0]:
            raise RtdeError(f"{self.where}: protocol version {PROTOCOL_VERSION} refused")
        reply = self._request(SETUP_OUTPUTS, struct.pack(">d", frequency_hz) + ",".join(RECIPE).encode())
        self.recipe_id = reply[0]
        types = tuple(reply[1:].decode("ascii", "replace").split(","))
        if types != EXPECTED_TYPES or self.recipe_id == 0:  # 0: the setup failed (e.g. the frequency)
            wrong = [f"{n}: {t}" for n, t, e in zip(RECIPE, types, EXPECTED_TYPES, strict=False) if t != e]
            detail = ", ".join(wrong) or f"above the controller's rate, or recipe id {self.recipe_id}"
            raise RtdeError(f"{self.where}: output recipe refused at {frequency_hz:g} Hz ({detail})")
        self._data = struct.Struct(">B" + "".join(FORMATS[t] for t in types))
        reply = self._request(START, b"")
        if not reply or not reply[0]:
            raise RtdeError(f"{self.where}: start refused")
        self._sock.settimeout(None)  # from here on, `read` blocks until the controller sends

    def _request(self, kind: int, payload: bytes) -> bytes:
        self._sock.sendall(HEADER.pack(HEADER.size + len(payload), kind) + payload)
        while True:
            got, body = self._next()
            if got == kind:
                return body  # text messages and a package of an earlier stream are skipped

    def _next(self) -> tuple[int, bytes]:
        """The next whole package: (type, payload)."""
        buf = self._buf
        while True:
            if len(buf) >= HEADER.size:
                size, kind = HEADER.unpack_from(buf)
                if size < HEADER.size:
                    raise RtdeError(f"{self.where}: malformed package (size {size})")
                if len(buf) >= size:
                    body = bytes(buf[HEADER.size : size])
                    del buf[:size]
                    return kind, body
            try:
                chunk = self._sock.recv(65536)
            except OSError as e:
                raise RtdeError(f"{self.where}: {e}") from None
            if not chunk:
                raise RtdeError(f"{self.where}: the controller closed the connection")
            buf += chunk

    def read(self) -> StreamState:
        """Block until the next data package of our recipe; its arrival is CLOCK_MONOTONIC when
        the read returned."""
        while True:
            kind, body = self._next()
            if kind == DATA_PACKAGE and body and body[0] == self.recipe_id and len(body) == self._data.size:
                return self._unpack(self._data.unpack(body), time.monotonic_ns())

    @staticmethod
    def _unpack(v: tuple[float | int | bool, ...], arrival_ns: int) -> StreamState:
        return StreamState(
            stamp=float(v[1]),
            arrival_ns=arrival_ns,
            connected=True,
            q_rad=tuple(map(float, v[2:8])),
            dq_rad_s=tuple(map(float, v[8:14])),
            target_moment_nm=tuple(map(float, v[14:20])),
            robot_mode=int(v[20]),
            safety_mode=int(v[21]),
            runtime_state=int(v[22]),
            script_running=bool(int(v[23]) & ROBOT_PROGRAM_RUNNING),
            tcp_force=tuple(map(float, v[24:30])),
            speed_scaling=float(v[30]),
            digital_inputs=int(v[31]),
        )

    def close(self) -> None:
        """Closed: a `read` blocked in another thread returns with an RtdeError."""
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
