"""RTDE on port 30004: protocol version 2, as the RTDE guide describes it.

Every message is `uint16 size` (header included) + `uint8 type` + payload, big-endian:

- 'V' request protocol version (uint16) -> uint8 accepted (only version 2 is);
- 'v' get URControl version -> 4 × uint32 (major, minor, bugfix, build);
- 'O' setup outputs: double frequency + comma-separated names -> uint8 recipe id (0 if a name
  is unknown) + comma-separated types (NOT_FOUND for the unknown ones);
- 'I' setup inputs: names -> uint8 recipe id (0 if a name is unknown or written by another
  client) + types (NOT_FOUND, IN_USE);
- 'S' start / 'P' pause -> uint8 accepted; once started, 'U' data packages (uint8 recipe id +
  the output recipe's fields) every `round(rate / frequency)` controller cycles;
- 'U' from the client: uint8 input recipe id + that recipe's fields, written into the inputs;
- 'M' text message (uint8 length + text + uint8 length + source + uint8 warning level), sent
  to a started client when one of its packages is refused; a client's own are logged.

A session's data packages are packed in the controller's cycle and sent by the session's
thread, newest first: if the client reads too slowly, older packages are skipped, as the RTDE
guide says the controller does.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import struct
import threading
import time
from collections.abc import Callable

from orccadd.runtime.threads import ThreadGroup
from orccadd.ursim.controller import UrController
from orccadd.ursim.fields import IN_USE, NOT_FOUND, InputRecipe, OutputRecipe, RtdeType

SENDER_JOIN_S = 2.0  # a session's sender, woken by its close, ends within a send
log = logging.getLogger("orccadd.ursim")

PROTOCOL_VERSION = 2
HEADER = struct.Struct(">HB")
REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")
MAX_INPUT_RECIPES = 255
WARNING_LEVEL_WARNING = 1


class Stall:
    """An injected stall of every RTDE data stream: no package leaves before `until_s`
    (CLOCK_MONOTONIC); later ones carry the newest data."""

    def __init__(self) -> None:
        self.until_s = 0.0

    def hold(self, duration_s: float) -> None:
        self.until_s = max(self.until_s, time.monotonic() + duration_s)

    def active(self) -> bool:
        return self.until_s > 0.0 and time.monotonic() < self.until_s


def frame(kind: int, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def text_message(text: str, source: str = "RTDE", level: int = WARNING_LEVEL_WARNING) -> bytes:
    msg, src = text.encode()[:255], source.encode()[:255]
    return frame(TEXT_MESSAGE, bytes([len(msg)]) + msg + bytes([len(src)]) + src + bytes([level]))


def _recv_exact(conn: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = conn.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("closed by the client")
        buf += chunk
    return bytes(buf)


class RtdeSession:
    """One RTDE client: its recipes, its started/paused state and its data stream."""

    def __init__(self, conn: socket.socket, ctl: UrController, stall: Stall) -> None:
        self.conn = conn
        self.ctl = ctl
        self.stall = stall
        self.output: OutputRecipe | None = None
        self.output_id = 0
        self.decimation = 1
        self.inputs: dict[int, InputRecipe] = {}
        self.started = False
        self.sent = 0
        self.skipped = 0
        self._send_lock = threading.Lock()
        self._latest: bytes | None = None
        self._wake = threading.Event()
        self._closed = False

    # ---- the connection -------------------------------------------------------------------
    def serve(self) -> None:
        """The client's requests, in this (the connection's) thread; its packages are sent by a
        thread of the session's own, ended and joined with it."""
        sender = ThreadGroup("rtde-session")
        sender.start(self._send_loop, name="send")
        try:
            while True:
                size, kind = HEADER.unpack(_recv_exact(self.conn, HEADER.size))
                if size < HEADER.size:
                    log.warning("RTDE: message of size %d from a client: closing it", size)
                    return
                self._handle(kind, _recv_exact(self.conn, size - HEADER.size))
        except (ConnectionError, OSError):
            pass
        finally:
            self._close()
            with contextlib.suppress(OSError):  # a sender blocked in a send to a full socket ends too
                self.conn.shutdown(socket.SHUT_RDWR)
            sender.join(SENDER_JOIN_S)

    def _close(self) -> None:
        self._closed = True
        self._wake.set()
        with self.ctl.lock:
            if self._offer in self.ctl.subscribers:
                self.ctl.subscribers.remove(self._offer)
            for name in [n for n, owner in self.ctl.input_owner.items() if owner is self]:
                del self.ctl.input_owner[name]

    def _send(self, data: bytes) -> None:
        with self._send_lock:
            self.conn.sendall(data)

    def _send_loop(self) -> None:
        while not self._closed:
            self._wake.wait()
            self._wake.clear()
            # the package is taken and sent under the send lock: a pause reply (which clears
            # `_latest` first) can never overtake a package taken before it
            with self._send_lock:
                with self.ctl.lock:
                    data, self._latest = self._latest, None
                if data is None or self._closed:
                    continue
                try:
                    self.conn.sendall(data)
                except OSError:
                    return
            self.sent += 1

    def _offer(self, cycle: int) -> None:
        """Called by the controller's cycle (lock held): pack this cycle's package if due."""
        if self.output is None or cycle % self.decimation or self.stall.active():
            return
        if self._latest is not None:
            self.skipped += 1
            self.ctl.rtde_packages_skipped += 1
        self._latest = frame(DATA_PACKAGE, bytes([self.output_id]) + self.output.pack())
        self._wake.set()

    # ---- messages -------------------------------------------------------------------------
    def _handle(self, kind: int, payload: bytes) -> None:
        if kind == DATA_PACKAGE:
            self._input_package(payload)
        elif kind == REQUEST_PROTOCOL_VERSION:
            version = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else 0
            self._send(frame(kind, bytes([int(version == PROTOCOL_VERSION)])))
        elif kind == GET_URCONTROL_VERSION:
            self._send(frame(kind, struct.pack(">4I", *self.ctl.series.version)))
        elif kind == SETUP_OUTPUTS:
            self._send(frame(kind, self._setup_outputs(payload)))
        elif kind == SETUP_INPUTS:
            self._send(frame(kind, self._setup_inputs(payload)))
        elif kind == START:
            self._start()
        elif kind == PAUSE:
            self._pause()
        elif kind == TEXT_MESSAGE:
            log.info(
                "RTDE client says: %s",
                payload[1 : 1 + payload[0]].decode(errors="replace") if payload else "",
            )
        else:
            log.warning("RTDE: unknown message type %r from a client", chr(kind))

    def _setup_outputs(self, payload: bytes) -> bytes:
        if len(payload) < 8:
            return b"\x00"
        (frequency,) = struct.unpack(">d", payload[:8])
        names = [n for n in payload[8:].decode(errors="replace").split(",") if n]
        found = [self.ctl.fields.output_field(n) for n in names]
        types = [NOT_FOUND if f is None else f[0].name for f in found]
        rate = self.ctl.series.rate_hz
        ok = bool(names) and None not in found and 0.0 < frequency <= rate
        if ok:
            with self.ctl.lock:
                self.output = OutputRecipe(
                    names, [f[0] for f in found if f], [f[1] for f in found if f], frequency
                )
                self.output_id = 1
                self.decimation = max(1, round(rate / frequency))
        elif not 0.0 < frequency <= rate:
            log.warning("RTDE: output frequency %g Hz refused (must be in (0, %g])", frequency, rate)
        else:
            unknown = [n for n, f in zip(names, found, strict=True) if f is None]
            log.warning("RTDE: output recipe refused, unknown fields: %s", ", ".join(unknown) or "none")
        return bytes([1 if ok else 0]) + ",".join(types).encode()

    def _setup_inputs(self, payload: bytes) -> bytes:
        names = [n for n in payload.decode(errors="replace").split(",") if n]
        with self.ctl.lock:
            found = [self.ctl.fields.input_field(n) for n in names]
            types: list[str] = []
            for n, f in zip(names, found, strict=True):
                owner = self.ctl.input_owner.get(n)
                if f is None:
                    types.append(NOT_FOUND)
                elif owner is not None and owner is not self:
                    types.append(IN_USE)
                else:
                    types.append(f[0].name)
            ok = bool(names) and all(t in RtdeType.__members__ for t in types)
            ok = ok and len(self.inputs) < MAX_INPUT_RECIPES
            if not ok:
                refused = [
                    f"{n} ({t})" for n, t in zip(names, types, strict=True) if t in (NOT_FOUND, IN_USE)
                ]
                log.warning("RTDE: input recipe refused: %s", ", ".join(refused) or "too many recipes")
                return b"\x00" + ",".join(types).encode()
            recipe_id = len(self.inputs) + 1
            self.inputs[recipe_id] = InputRecipe(
                recipe_id, names, [f[0] for f in found if f], [f[1] for f in found if f]
            )
            for n in names:
                self.ctl.input_owner[n] = self
        return bytes([recipe_id]) + ",".join(types).encode()

    def _start(self) -> None:
        with self.ctl.lock:
            self.started = True
            if self.output is not None and self._offer not in self.ctl.subscribers:
                self.ctl.subscribers.append(self._offer)
        self._send(frame(START, b"\x01"))

    def _pause(self) -> None:
        with self.ctl.lock:
            self.started = False
            if self._offer in self.ctl.subscribers:
                self.ctl.subscribers.remove(self._offer)
            self._latest = None
        self._send(frame(PAUSE, b"\x01"))

    def _input_package(self, payload: bytes) -> None:
        recipe = self.inputs.get(payload[0]) if payload else None
        if recipe is None or len(payload) - 1 != recipe.size:
            why = "unknown input recipe id" if recipe is None else "wrong size for its recipe"
            log.warning("RTDE: data package refused: %s", why)
            if self.started:
                self._send(text_message(f"RTDE data package refused: {why}"))
            return
        values = recipe.unpack(payload[1:])
        with self.ctl.lock:
            recipe.apply(values)
            self.ctl.inputs_written(recipe.names)


def rtde_handler(ctl: UrController, stall: Stall) -> Callable[[socket.socket], None]:
    """The `net.Server` handler serving one RTDE connection."""

    def handle(conn: socket.socket) -> None:
        RtdeSession(conn, ctl, stall).serve()

    return handle
