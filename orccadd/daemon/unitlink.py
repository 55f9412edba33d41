"""The link between the automaton's process and a resource's unit process (issue 44, item 2;
work in progress on branch unit-process: not wired into the daemon yet).

What crosses at every tick goes through shared memory (`unitshm.UnitChannel`: switch requests,
events) and the unit's telemetry block (its ticks, heartbeat, active task). The rest — a mission
to build, a tune, a safe stop, a fault to inject, the unit's end — crosses this link: a stream
socket pair, the unit's end inherited by its process, each message one frame (a 4-byte length,
then the pickled dict: both ends are the daemon's own processes, nothing else can reach them).

Requests carry `op` and `id`; the unit answers each with the same `id` and `ok` (and what the
op returns) or `error` (words). The unit also speaks unasked: `holding` once its loop ticks,
`failed` when its control thread ends on an exception.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from orccadd.daemon.unitshm import UnitChannel
from orccadd.errors import OrccaddError

FRAME = struct.Struct("!I")
FRAME_MAX = 64 << 20  # a mission's compiled form fits many times over
START_WAIT_S = 20.0  # the longest a unit may take to configure its resource and hold it


class UnitLinkError(OrccaddError):
    """The unit process is gone, broke the link, or refused."""


def send_frame(sock: socket.socket, msg: dict[str, Any]) -> None:
    data = pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL)
    sock.sendall(FRAME.pack(len(data)) + data)


def recv_frame(sock: socket.socket) -> dict[str, Any] | None:
    """The next message; None at the end of the link."""
    head = _recv_exactly(sock, FRAME.size)
    if head is None:
        return None
    (n,) = FRAME.unpack(head)
    if n > FRAME_MAX:
        raise UnitLinkError(f"a frame of {n} bytes on a unit's link (at most {FRAME_MAX})")
    body = _recv_exactly(sock, n)
    if body is None:
        raise UnitLinkError("a unit's link ended inside a frame")
    msg = pickle.loads(body)
    if not isinstance(msg, dict):
        raise UnitLinkError(f"a unit's link carried a {type(msg).__name__}, not a message")
    return msg


def _recv_exactly(sock: socket.socket, n: int) -> bytes | None:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            if buf:
                raise UnitLinkError("a unit's link ended inside a frame")
            return None
        buf += chunk
    return bytes(buf)


class UnitLink:
    """The automaton process's end: the unit process started, its channel, its messages.

    `start` returns once the unit holds its resource (its `holding` message). `call` sends a
    request and waits for its answer (for tests and startup; the automaton thread will poll).
    Unasked messages are kept in `told`, in order."""

    def __init__(
        self,
        station_path: str | Path,
        resource: str,
        telemetry: str,
        wake_fd: int,
        *,
        simulate: bool = False,
        in_process_sim: bool = False,
        spin_us: float = 0.0,
        channel: UnitChannel | None = None,
        station: tuple[list[str], int, str] | None = None,
    ) -> None:
        """`channel`: the unit's shared channel (a unit started again takes its predecessor's:
        the automaton's side keeps it); None: a new one, closed with this link. `station`: every
        unit's channel by name in the station's order, this unit's index among them, and the
        station's try-lock file (for the reactions it takes in its ticks; None: it takes none)."""
        self.resource = resource
        self.closed = False
        self.own_channel = channel is None
        self.channel = channel if channel is not None else UnitChannel.create()
        self.station = station
        self.start_args = (station_path, resource, telemetry, wake_fd, simulate, in_process_sim, spin_us)
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock = ours
        argv = [
            sys.executable,
            "-m",
            "orccadd.daemon.unitproc",
            "--station",
            str(station_path),
            "--resource",
            resource,
            "--channel",
            self.channel.name,
            "--telemetry",
            telemetry,
            "--link-fd",
            str(theirs.fileno()),
            "--wake-fd",
            str(wake_fd),
            "--spin-us",
            str(spin_us),
        ]
        if station is not None:
            names, index, lock = station
            argv += ["--channels", ",".join(names), "--index", str(index), "--lock", lock]
        argv += ["--simulate"] if simulate else []
        argv += ["--in-process-sim"] if in_process_sim else []
        try:
            self.proc = subprocess.Popen(argv, pass_fds=(theirs.fileno(), wake_fd))
        except OSError:
            self.close()
            raise
        finally:
            theirs.close()
        self.pidfd = os.pidfd_open(self.proc.pid)
        self.told: list[dict[str, Any]] = []  # come, not taken by `call` nor `receive` yet
        self.seen: list[dict[str, Any]] = []  # taken by `receive` (tests read them)
        self.holding: dict[str, Any] = {}
        self.refused = ""  # why the unit could not start (its words), "" if it did
        self._next_id = 0

    def wait_holding(self, timeout_s: float = START_WAIT_S) -> dict[str, Any]:
        """The unit's `holding` message (its pid, its plant's, its tasks' names), once its loop has
        ticked; `UnitLinkError` with what it said if it ended or did not hold in time."""
        end = time.monotonic() + timeout_s
        while not self.holding:
            try:
                msg = self._recv(end - time.monotonic())
            except UnitLinkError:
                if self.refused:  # its own words: what it could not do
                    raise UnitLinkError(self.refused) from None
                raise
            if msg is None:
                raise UnitLinkError(f"unit {self.resource}: did not hold its resource within {timeout_s:g} s")
            self._told(msg)
        return self.holding

    def send(self, op: str, **args: Any) -> int:
        """Request `op` without waiting; its id (its answer carries it)."""
        self._next_id += 1
        rid = self._next_id
        try:
            send_frame(self.sock, {"op": op, "id": rid, **args})
        except OSError as e:
            raise UnitLinkError(f"unit {self.resource}: its link is gone ({e})") from None
        return rid

    def call(self, op: str, timeout_s: float = 10.0, **args: Any) -> dict[str, Any]:
        """Request `op`, wait for its answer; `UnitLinkError` with the unit's words if refused.
        What else arrives meanwhile goes to `told`."""
        rid = self.send(op, **args)
        end = time.monotonic() + timeout_s
        while True:
            msg = self._recv(end - time.monotonic())
            if msg is None:
                raise UnitLinkError(f"unit {self.resource}: no answer to {op} within {timeout_s:g} s")
            if msg.get("id") == rid:
                if "error" in msg:
                    raise UnitLinkError(f"unit {self.resource}: {msg['error']}")
                return msg
            self._told(msg)

    def receive(self, timeout_s: float = 0.0) -> list[dict[str, Any]]:
        """Every message not taken yet by a `call` — those that came while one waited, then
        what arrives within `timeout_s` — in order, once each. `UnitLinkError` once the unit's
        process has ended (what it said before comes first)."""
        end = time.monotonic() + timeout_s
        try:
            while (msg := self._recv(end - time.monotonic())) is not None:
                self._told(msg)
        finally:
            got, self.told = self.told, []
            self.seen.extend(got)
        return got

    def _recv(self, timeout_s: float) -> dict[str, Any] | None:
        ready, _, _ = select.select([self.sock.fileno(), self.pidfd], [], [], max(0.0, timeout_s))
        if self.sock.fileno() in ready:
            msg = recv_frame(self.sock)
            if msg is not None:
                return msg
        if ready:
            code = self.proc.wait(timeout=5.0)
            raise UnitLinkError(f"unit {self.resource}: its process ended (exit {code})")
        return None

    def _told(self, msg: dict[str, Any]) -> None:
        if msg.get("op") == "holding":
            self.holding = msg
        elif msg.get("op") == "refused":
            self.refused = str(msg.get("error", "refused"))
        self.told.append(msg)

    def end(self, timeout_s: float = 10.0) -> int:
        """The unit stops its loop, releases its resource and exits; its exit code (killed if it
        did not end in time)."""
        if self.proc.poll() is None:
            with contextlib.suppress(OSError):
                send_frame(self.sock, {"op": "end", "id": 0})
            try:
                self.proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.close()
        return self.proc.returncode

    def close(self) -> None:
        """Everything of this end released (again: nothing more)."""
        if self.closed:
            return
        self.closed = True
        self.sock.close()
        if hasattr(self, "pidfd"):
            os.close(self.pidfd)
        if self.own_channel:
            self.channel.close()

    def again(self) -> UnitLink:
        """A new unit process for the same resource, on the same channel (this one ended); this
        link's channel passes to it."""
        path, resource, tel, wake_fd, simulate, in_process_sim, spin_us = self.start_args
        link = UnitLink(
            path, resource, tel, wake_fd, simulate=simulate, in_process_sim=in_process_sim, spin_us=spin_us,
            channel=self.channel, station=self.station,
        )  # fmt: skip
        link.own_channel, self.own_channel = self.own_channel, False
        self.close()
        return link
