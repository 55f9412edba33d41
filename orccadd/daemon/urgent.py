"""`<socket>.urgent`: `abort` and `stop` straight to the real-time process.

Every other request goes through the command daemon, a time-shared process that serves every
client in turn: under a load of clients an operator's abort waited there for milliseconds
(`benchmarks/abort_latency.py`). On this socket the automaton thread itself (SCHED_FIFO, above the
control thread) reads the request the moment it arrives and the control thread applies it at
the next tick. It takes nothing else: one JSON line per request (`{"id": 1, "cmd": "abort"}`),
one reply line, from a peer with the control role (SO_PEERCRED), a few connections at a time,
each line at most `LINE_MAX` bytes; anything else gets one error line and the connection closed.
`orccadctl abort` and `orccadctl stop` use it when it is there.

Its few places cannot be held against an operator: a new connection when all are taken closes
the one that has gone longest without a complete request (a peer that trickles a byte now and
then keeps none), a request line begun must end within `LINE_WAIT_S`, and a connection without
a request for `IDLE_S` is closed. `orccadctl` falls back to the main socket, which keeps places
for abort and stop too, if this one refuses it.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import socket
import stat
import time
from collections.abc import Callable
from typing import Any

from orccadd.wire.commands import URGENT_COMMANDS, ProtocolError, Role, parse_request
from orccadd.wire.roles import RoleConfig, Roles, peer_credentials
from orccadd.wire.socketdir import bind_with_mode

log = logging.getLogger("orccadd")

LINE_MAX = 4096  # bytes of one request line, its newline not counted
CLIENTS_MAX = 8
IDLE_S = 10.0  # a connection without a complete request for this long is closed
LINE_WAIT_S = 1.0  # a request line, once begun, is complete within this or the connection closed


class _Conn:
    """One connection: its socket, the line being read, and when it last completed a request
    (or connected) and began the current line (monotonic s; 0: no line begun)."""

    __slots__ = ("begun_s", "buf", "since_s", "sock")

    def __init__(self, sock: socket.socket, now_s: float) -> None:
        self.sock = sock
        self.buf = bytearray()
        self.since_s = now_s
        self.begun_s = 0.0


class UrgentSocket:
    """The listener and its connections, served from the automaton thread's poll loop."""

    def __init__(
        self,
        path: str,
        roles: RoleConfig,
        gid: int,
        handle: Callable[[tuple[Any, str, dict[str, Any]]], dict[str, Any]],
    ) -> None:
        self.path = path
        self.roles = Roles(roles)
        self.handle = handle
        with contextlib.suppress(FileNotFoundError):  # a socket left over (checked at startup)
            if stat.S_ISSOCK(os.lstat(path).st_mode):
                os.unlink(path)
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK)
        bind_with_mode(s, path, 0o117)
        if gid >= 0:
            os.chown(path, -1, gid)
        s.listen(CLIENTS_MAX)
        self.listener = s
        self.clients: dict[int, _Conn] = {}

    def fds(self) -> list[int]:
        return [self.listener.fileno(), *self.clients]

    def on_readable(self, fd: int) -> None:
        if fd == self.listener.fileno():
            self._accept()
        elif fd in self.clients:
            self._read(fd)

    def expire(self) -> None:
        """Close connections idle for `IDLE_S`, or slower than `LINE_WAIT_S` to finish a line
        (called now and then)."""
        now = time.monotonic()
        for fd, c in list(self.clients.items()):
            if c.begun_s and now - c.begun_s > LINE_WAIT_S:
                self._close(fd, f"request line not completed within {LINE_WAIT_S:g} s")
            elif now - c.since_s > IDLE_S:
                self._close(fd)

    def close(self) -> None:
        for fd in list(self.clients):
            self._close(fd)
        self.listener.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)

    def _accept(self) -> None:
        try:
            conn, _ = self.listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        conn.setblocking(False)
        _, uid, gid = peer_credentials(conn)
        if self.roles.role(uid, gid) is not Role.CONTROL:
            self._refuse(conn, None, "not authorised: abort and stop need the control role")
            return
        if len(self.clients) >= CLIENTS_MAX:  # the longest without a request makes way
            oldest = min(self.clients, key=lambda fd: self.clients[fd].since_s)
            self._close(oldest, f"closed to make way for a newer connection (max {CLIENTS_MAX})")
        self.clients[conn.fileno()] = _Conn(conn, time.monotonic())
        self._read(conn.fileno())  # the request usually came with the connection

    def _read(self, fd: int) -> None:
        c = self.clients[fd]
        try:
            data = c.sock.recv(LINE_MAX + 1)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._close(fd)
            return
        buf = c.buf
        if not buf:
            c.begun_s = time.monotonic()
        buf += data
        while (end := buf.find(b"\n")) >= 0:
            if end > LINE_MAX:
                break
            line = bytes(buf[:end])
            del buf[: end + 1]
            c.since_s = time.monotonic()
            c.begun_s = c.since_s if buf else 0.0
            self._answer(fd, c.sock, line)
            if fd not in self.clients:
                return
        if len(buf) > LINE_MAX:
            self._close(fd, f"request longer than {LINE_MAX} bytes")

    def _answer(self, fd: int, conn: socket.socket, line: bytes) -> None:
        try:
            rid, cmd, args = parse_request(line)  # decoded once, here
        except ProtocolError as e:
            rid, cmd, args = e.rid, None, {}
        if cmd not in URGENT_COMMANDS:
            self._close(fd, "this socket takes abort and stop only (other commands: the main socket)", rid)
            return
        reply = self.handle((rid, cmd, args))
        log.info("%s from the urgent socket: %s", cmd, "ok" if reply.get("ok") else reply.get("error"))
        self._send(conn, reply)

    def _send(self, conn: socket.socket, reply: dict[str, Any]) -> None:
        with contextlib.suppress(OSError):  # a full buffer: the client does not read; its loss
            conn.send(json.dumps(reply, default=str).encode() + b"\n")

    def _refuse(self, conn: socket.socket, rid: Any, error: str) -> None:
        self._send(conn, {"id": rid, "ok": False, "error": error})
        with contextlib.suppress(OSError):  # what it sent unread would turn the close into a reset
            for _ in range(16):
                if not conn.recv(LINE_MAX):
                    break
        conn.close()

    def _close(self, fd: int, error: str = "", rid: Any = None) -> None:
        conn = self.clients.pop(fd).sock
        if error:
            self._refuse(conn, rid, error)
        else:
            conn.close()
