"""`<socket>.urgent`: `abort` and `stop` straight to the real-time process.

Every other request goes through the command daemon, a time-shared process that serves every
client in turn: under a load of clients an operator's abort waited there for milliseconds
(`benchmarks/abort_latency.py`). On this socket the automaton thread itself (SCHED_FIFO, above the
control thread) reads the request the moment it arrives and the control thread applies it at
the next tick. It takes nothing else: one JSON line per request (`{"id": 1, "cmd": "abort"}`),
one reply line, from a peer with the control role (SO_PEERCRED), a few connections at a time,
each line at most `LINE_MAX` bytes; anything else gets one error line and the connection closed.
`orccadctl abort` and `orccadctl stop` use it when it is there.
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

from orccadd.wire.commands import Role
from orccadd.wire.roles import RoleConfig, Roles, peer_credentials

log = logging.getLogger("orccadd")

URGENT_COMMANDS = frozenset({"abort", "stop"})
LINE_MAX = 4096
CLIENTS_MAX = 8
IDLE_S = 10.0


class UrgentSocket:
    """The listener and its connections, served from the automaton thread's poll loop."""

    def __init__(
        self, path: str, roles: RoleConfig, gid: int, handle: Callable[[bytes], dict[str, Any]]
    ) -> None:
        self.path = path
        self.roles = Roles(roles)
        self.handle = handle
        with contextlib.suppress(FileNotFoundError):  # a socket left over (checked at startup)
            if stat.S_ISSOCK(os.lstat(path).st_mode):
                os.unlink(path)
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK)
        old = os.umask(0o117)
        try:
            s.bind(path)
        finally:
            os.umask(old)
        if gid >= 0:
            os.chown(path, -1, gid)
        s.listen(CLIENTS_MAX)
        self.listener = s
        self.clients: dict[int, tuple[socket.socket, bytearray, float]] = {}

    def fds(self) -> list[int]:
        return [self.listener.fileno(), *self.clients]

    def on_readable(self, fd: int) -> None:
        if fd == self.listener.fileno():
            self._accept()
        elif fd in self.clients:
            self._read(fd)

    def expire(self) -> None:
        """Close connections idle for `IDLE_S` (called now and then)."""
        now = time.monotonic()
        for fd, (_, _, since) in list(self.clients.items()):
            if now - since > IDLE_S:
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
        if len(self.clients) >= CLIENTS_MAX:
            self._refuse(conn, None, f"too many connections on the urgent socket (max {CLIENTS_MAX})")
            return
        self.clients[conn.fileno()] = (conn, bytearray(), time.monotonic())

    def _read(self, fd: int) -> None:
        conn, buf, _ = self.clients[fd]
        try:
            data = conn.recv(LINE_MAX)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._close(fd)
            return
        buf += data
        self.clients[fd] = (conn, buf, time.monotonic())
        while (end := buf.find(b"\n")) >= 0:
            line = bytes(buf[:end])
            del buf[: end + 1]
            self._answer(fd, conn, line)
            if fd not in self.clients:
                return
        if len(buf) > LINE_MAX:
            self._close(fd, f"request longer than {LINE_MAX} bytes")

    def _answer(self, fd: int, conn: socket.socket, line: bytes) -> None:
        rid: Any = None
        try:
            msg = json.loads(line)
            rid = msg.get("id") if isinstance(msg, dict) else None
            cmd = msg.get("cmd") if isinstance(msg, dict) else None
        except (ValueError, RecursionError):
            cmd = None
        if cmd not in URGENT_COMMANDS:
            self._close(fd, "this socket takes abort and stop only (other commands: the main socket)", rid)
            return
        reply = self.handle(line)
        log.info("%s from the urgent socket: %s", cmd, "ok" if reply.get("ok") else reply.get("error"))
        self._send(conn, reply)

    def _send(self, conn: socket.socket, reply: dict[str, Any]) -> None:
        with contextlib.suppress(OSError):  # a full buffer: the client does not read; its loss
            conn.send(json.dumps(reply, default=str).encode() + b"\n")

    def _refuse(self, conn: socket.socket, rid: Any, error: str) -> None:
        self._send(conn, {"id": rid, "ok": False, "error": error})
        conn.close()

    def _close(self, fd: int, error: str = "", rid: Any = None) -> None:
        conn, _, _ = self.clients.pop(fd)
        if error:
            self._refuse(conn, rid, error)
        else:
            conn.close()
