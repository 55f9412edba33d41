"""The drive simulator's own socketcand (raw mode) client, for the userspace bus.

python-can's `socketcand` client (what the controller uses, stock) makes one system call per
frame sent and parses frames one at a time. The drive simulator answers every SYNC with one
TPDO per axis and must keep up with ~4,000 frames/s on a shared core: this client reads all
queued frames in one call and, like a CAN controller's transmit mailboxes, queues a cycle's
frames (`send`) and hands them to the bus in one write (`send_queued`, after each batch).
"""

from __future__ import annotations

import select
import socket
from collections import deque
from typing import Any

import can

HANDSHAKE_TIMEOUT_S = 10.0


class QueuedSocketcandBus(can.BusABC):
    def __init__(self, channel: str, host: str, port: int, **kwargs: Any) -> None:
        self._sock = socket.create_connection((host, port), timeout=HANDSHAKE_TIMEOUT_S)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._buf = b""
        self._rx: deque[can.Message] = deque()
        self._tx: list[bytes] = []
        self._expect(b"< hi >")
        self._sock.sendall(f"< open {channel} >".encode())
        self._expect(b"< ok >")
        self._sock.sendall(b"< rawmode >")
        self._expect(b"< ok >")
        self._sock.settimeout(None)
        self.channel_info = f"socketcand {host}:{port} {channel} (queued)"
        super().__init__(channel=channel, **kwargs)

    def _expect(self, word: bytes) -> None:
        while b">" not in self._buf:
            chunk = self._sock.recv(4096)
            if not chunk:
                raise can.CanOperationError(f"socketcand server closed the connection (expected {word!r})")
            self._buf += chunk
        end = self._buf.index(b">") + 1
        got, self._buf = self._buf[:end].strip(), self._buf[end:]
        if got != word:
            raise can.CanOperationError(f"socketcand handshake: expected {word!r}, got {got!r}")

    def fileno(self) -> int:
        """The connection's descriptor, readable when frames (or the server's close) are there;
        frames already read and parsed are not counted: drain with `recv(0.0)` before waiting."""
        return self._sock.fileno()

    # ---- receive ------------------------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._rx:
            ready, _, _ = select.select([self._sock], [], [], timeout)
            if not ready:
                return None, False
            chunk = self._sock.recv(1 << 16)
            if not chunk:
                raise can.CanOperationError("socketcand server closed the connection")
            self._parse(chunk)
        return (self._rx.popleft() if self._rx else None), False

    def _parse(self, chunk: bytes) -> None:
        buf = self._buf + chunk
        start = 0
        while True:
            end = buf.find(b">", start)
            if end < 0:
                break
            parts = buf[start:end].split()
            start = end + 1
            # "< frame ID SECONDS DATA >" (DATA absent for an empty frame)
            if len(parts) >= 4 and parts[1] == b"frame":
                ident = parts[2]
                self._rx.append(
                    can.Message(
                        arbitration_id=int(ident, 16),
                        is_extended_id=len(ident) > 3,
                        timestamp=float(parts[3]),
                        data=bytes.fromhex(parts[4].decode()) if len(parts) > 4 else b"",
                        channel=self.channel_info,
                    )
                )
        self._buf = buf[start:]

    # ---- send ---------------------------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Queue `msg`; `send_queued` writes the queue to the bus in order."""
        ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
        data = " ".join(f"{b:02X}" for b in msg.data)
        self._tx.append(f"< send {ident} {len(msg.data)} {data} >".encode())

    def send_queued(self) -> None:
        if self._tx:
            payload = b"".join(self._tx)
            self._tx.clear()
            try:
                self._sock.sendall(payload)
            except OSError as e:
                raise can.CanOperationError(f"socketcand send: {e}") from e

    def shutdown(self) -> None:
        super().shutdown()
        self._sock.close()
