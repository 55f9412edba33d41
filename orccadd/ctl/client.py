"""A small blocking client of the orccadd protocol (orccadd/cmdd/protocol.py)."""

from __future__ import annotations

import contextlib
import json
import os
import socket
from collections.abc import Iterator
from typing import Any

from orccadd.wire.schema import PROTOCOL_VERSION

DEFAULT_SOCKET = "/run/orccadd/orccadd.sock"


def default_socket() -> str:
    return os.environ.get("ORCCADD_SOCKET", DEFAULT_SOCKET)


def socket_help() -> str:
    return f"the daemon's socket (default: $ORCCADD_SOCKET, else {DEFAULT_SOCKET}; now {default_socket()})"


class ClientError(Exception):
    """The daemon cannot be reached, or answered with an error (the message is its words)."""


class Client:
    def __init__(self, path: str | None = None, timeout_s: float = 10.0) -> None:
        self.path = path or default_socket()
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(timeout_s)
        try:
            self.sock.connect(self.path)
        except OSError as e:
            self.sock.close()
            why = f"cannot reach orccadd at {self.path}: {e.strerror or e}"
            if isinstance(e, FileNotFoundError | ConnectionRefusedError):
                # orccadd opens its socket once the arm is configured: a bus's startup takes seconds
                why += " (orccadd is not running there, or is still starting up)"
            raise ClientError(why) from None
        self.file = self.sock.makefile("rb")
        self.next_id = 0

    def close(self) -> None:
        self.file.close()
        self.sock.close()

    def interrupt(self) -> None:
        """End the connection under a thread blocked reading a stream on it (a close alone
        would not wake it): its read ends as if the daemon had closed."""
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send_raw(self, data: bytes) -> dict[str, Any]:
        """Send bytes as they are; read one reply line (for protocol tests)."""
        self._sendall(data)
        return self._line()

    def _line(self) -> dict[str, Any]:
        try:
            line = self.file.readline()
        except ConnectionError as e:  # reset: never taken for our own stdout closing
            raise ClientError(f"orccadd at {self.path} dropped the connection: {e.strerror or e}") from None
        if not line:
            raise ClientError("orccadd closed the connection")
        reply: dict[str, Any] = json.loads(line)
        return reply

    def _sendall(self, data: bytes) -> None:
        """Send a request; if the daemon has closed the connection first (a refusal: too many
        clients, no role), `ClientError` with its words, else with the reason: a request that
        was not delivered is always an error, never taken for our own stdout closing."""
        try:
            self.sock.sendall(data)
        except ConnectionError as e:
            why = f"the request was not delivered to orccadd at {self.path}: {e.strerror or e}"
            try:
                self.sock.settimeout(0.5)
                line = self.file.readline()  # the refusal it sent before closing, if any
                refusal = json.loads(line).get("error") if line else None
            except (OSError, ValueError, AttributeError):
                refusal = None
            raise ClientError(f"{refusal} (not delivered)" if refusal else why) from None

    def _send(self, cmd: str, args: dict[str, Any]) -> int:
        self.next_id += 1
        msg = {"id": self.next_id, "cmd": cmd, "args": args, "protocol": PROTOCOL_VERSION}
        self._sendall((json.dumps(msg) + "\n").encode())
        return self.next_id

    def reply(self, cmd: str, **args: Any) -> dict[str, Any]:
        """The whole reply (ok or not)."""
        self._send(cmd, args)
        return self._line()

    def call(self, cmd: str, **args: Any) -> Any:
        """The result, or `ClientError` with the daemon's message."""
        r = self.reply(cmd, **args)
        if not r.get("ok"):
            raise ClientError(str(r.get("error")))
        return r.get("result")

    def stream(self, cmd: str, **args: Any) -> Iterator[dict[str, Any]]:
        """The stream items of a streaming command, until its final reply. No timeout: a follow on
        a quiet daemon waits as long as it is quiet (the daemon ends the stream if it goes)."""
        self._send(cmd, args)
        self.sock.settimeout(None)
        while True:
            r = self._line()
            if not r.get("ok"):
                raise ClientError(str(r.get("error")))
            if "stream" not in r:
                return
            yield r["stream"]
