"""The real-time process's end of its link to the command daemon (`orccadd.cmdd`): one
SOCK_SEQPACKET connection whose kernel buffer is the bounded command queue.

Requests are decoded once; abort, stop and a peer's signal are served the moment they arrive,
the rest in the control loops' slack (right after a tick of the fastest resource ended, so that
a command's Python work does not delay a tick), a bounded share per slack. Replies and pushes
never block: what the link has no room for waits in order (`outbox`); beyond `OUTBOX_MAX` the
oldest push goes first, then the oldest reply, each counted by kind and told to the command
daemon (`link_discarded`). A command daemon that attaches replaces the one before (its queued
requests and replies dropped: their client has gone).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import socket
import time
from collections import deque
from typing import Any

from orccadd.daemon.machine import Machine
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.wire.commands import COMMANDS, URGENT_COMMANDS, ProtocolError, parse_request
from orccadd.wire.socketdir import bind_with_mode

log = logging.getLogger("orccadd")

RT_MAX = 1 << 20  # largest message on the link to the command daemon (it refuses larger)
URGENT_MAX_BYTES = 4096  # an abort or a stop is a short message; longer ones are not looked into
RECEIVE_MAX = 256  # messages read per wake-up (the command daemon has fewer in flight)
SERVE_BUDGET_PERIODS = 0.3  # other requests served per slack; the rest at the next one
# messages to the command daemon waiting for room on the link (its kernel buffer full): beyond,
# the oldest push goes first, then the oldest reply; each one discarded is counted by kind
OUTBOX_MAX = 4096
DISCARD_LOG_S = 10.0  # a discarded message said at most this often (with the counts so far)


Request = tuple[Any, str, dict[str, Any]]  # (id, cmd, args), decoded and checked once


def decode(data: bytes) -> Request | dict[str, Any]:
    """A request as `parse_request` reads it (once per message in this process), or the error
    reply to send for it."""
    try:
        return parse_request(data)
    except ProtocolError as e:
        return {"id": e.rid, "ok": False, "error": str(e)}


# served the moment they arrive: abort and stop, and a peer's signal, which enters the automaton
# as a task's event does (one reaction, at this thread's priority, never a tick's work)
ON_ARRIVAL = URGENT_COMMANDS | {"cell_input"}


def one_way(rid: Any) -> bool:
    """A request id the command daemon awaits no reply to (negative: a peer's signal sent
    straight from its Zenoh thread)."""
    return isinstance(rid, int) and not isinstance(rid, bool) and rid < 0


def rt_socket_path(public: str) -> str:
    return public + ".rt"


class CommandLink:
    """The listening socket at `path` (0600: only this user; the command daemon runs as it),
    the command daemon's connection once it attaches, and the requests and replies between
    them. `machine` (set once built) serves the requests. Runs in the automaton thread."""

    def __init__(self, path: str) -> None:
        self.path = path
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK)
        bind_with_mode(s, path, 0o177)  # only this user: the command daemon runs as it
        s.listen(2)
        self.listener = s
        self.conn: socket.socket | None = None
        self.machine: Machine
        self.inbox: deque[Request] = deque()  # requests waiting for the loop's slack
        self.inbox_since_ns = 0
        self.pending: list[tuple[Any, Pending]] = []  # (request id, reply to complete)
        # to the command daemon when its link has room again, in order (`_send`); discarded:
        # by kind (`reply`, `one_way_error`, a push's name), told to it (`link_discarded`)
        self.outbox: deque[bytes] = deque()
        self.outbox_kinds: deque[str] = deque()
        self.discarded: dict[str, int] = {}
        self.discarded_told = 0  # the total the command daemon was last told of
        self.discard_logged_s = 0.0

    def fds(self) -> set[int]:
        """What the automaton thread polls for the link: the listener, the connection, and while
        requests wait, the pacing loop's slack."""
        out = {self.listener.fileno()}
        if self.conn is not None:
            out.add(self.conn.fileno())
        if self.inbox:
            out.add(self.machine.pacing.loop.slack_fd)
        return out

    @property
    def busy(self) -> bool:
        """Work waits: requests for the slack, replies to complete, messages for room."""
        return bool(self.inbox or self.pending or self.outbox)

    def on_readable(self, fd: int) -> bool:
        """`fd` is the link's (the listener or the connection): handled. False: not the link's."""
        if fd == self.listener.fileno():
            self._accept()
        elif self.conn is not None and fd == self.conn.fileno():
            self._receive()
        else:
            return False
        return True

    def after_work(self) -> None:
        """After each wake-up: queued requests (in the slack), replies completed, sends retried."""
        self._serve_inbox()
        self._complete_pending()
        self._flush()

    def close(self) -> None:
        for s in (self.conn, self.listener):
            if s is not None:
                s.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)

    def _accept(self) -> None:
        try:
            conn, _ = self.listener.accept()
        except BlockingIOError:
            return
        conn.setblocking(False)
        if self.conn is not None:  # a new command daemon attaches: it replaces the old link
            self.conn.close()
        self.conn = conn
        self.machine.mission.cell_output = self.push_cell_output
        self.inbox.clear()  # requests of the old link: their client has gone
        self.pending.clear()
        self.outbox.clear()  # ... and what was waiting to be sent on it
        self.outbox_kinds.clear()
        self.discarded_told = 0  # the new one is told the counts so far
        self.machine.note("command daemon attached")

    def _receive(self) -> None:
        """Queue what the command daemon sent, served in the loop's slack (`_serve_inbox`); abort
        and stop are served at once, whatever is queued (each acts at the next tick: the control
        thread applies the safe stop or the switch itself)."""
        conn = self.conn
        assert conn is not None
        for _ in range(RECEIVE_MAX):  # bounded work per wake-up
            try:
                data, _, flags, _ = conn.recvmsg(RT_MAX)
            except BlockingIOError:
                return
            except OSError:
                data, flags = b"", 0
            if not data:
                conn.close()
                self.conn = None
                self.machine.link_lost("command daemon disconnected")
                self.machine.publish()
                return
            if flags & socket.MSG_TRUNC:
                self._send({"id": None, "ok": False, "error": f"request longer than {RT_MAX} bytes"})
                continue
            req = decode(data)
            if isinstance(req, dict):
                self._send(req)
                continue
            if req[1] in ON_ARRIVAL and len(data) <= URGENT_MAX_BYTES:
                self._serve(req)  # on arrival, ahead of any queue
                continue
            if not self.inbox:
                self.inbox_since_ns = time.monotonic_ns()
                self.machine.pacing.loop.want_slack()
            self.inbox.append(req)

    def _serve_inbox(self) -> None:
        """Handle queued requests right after a tick ended (or, if the loop is stopped or late,
        after two periods: there is nothing to keep out of the way of)."""
        if not self.inbox:
            return
        pacing = self.machine.pacing
        loop = pacing.loop
        period_ns = pacing.cfg.control_period_s * 1e9
        now = time.monotonic_ns()
        slack = False
        with contextlib.suppress(BlockingIOError):
            slack = bool(os.read(loop.slack_fd, 64))
        if not slack and now - self.inbox_since_ns < 2 * period_ns:
            return
        end = now + SERVE_BUDGET_PERIODS * period_ns
        while self.inbox and time.monotonic_ns() < end:
            self._serve(self.inbox.popleft())
        if self.inbox:  # the rest after the next tick
            self.inbox_since_ns = time.monotonic_ns()
            loop.want_slack()

    def _serve(self, req: Request) -> None:
        rid, reply = self.handle(req)
        if isinstance(reply, Pending):
            self.pending.append((rid, reply))
        elif not one_way(rid) or not reply.get("ok"):
            # a one-way request (a peer's signal sent straight from Zenoh's thread, a negative
            # id) waits for no reply: only a refusal goes back, for the command daemon to say
            self._send(reply)

    def _complete_pending(self) -> None:
        if not self.pending:
            return
        now = time.monotonic_ns()
        still: list[tuple[Any, Pending]] = []
        for rid, p in self.pending:
            try:
                result = p.poll()
                if result is None and now >= p.deadline_ns:
                    result = p.expire()
            except CommandError as e:
                self._send({"id": rid, "ok": False, "error": str(e)})
                continue
            except Exception as e:  # a bug must not take the automaton thread down
                log.exception("pending reply to request %s failed", rid)
                self._send({"id": rid, "ok": False, "error": f"internal error: {type(e).__name__}: {e}"})
                continue
            if result is None:
                still.append((rid, p))
            else:
                self.machine.publish()  # first: a `status` after this reply sees what it changed
                self._send({"id": rid, "ok": True, "result": result})
        if len(still) != len(self.pending):
            self.machine.publish()  # a reply went out: the state it changed
        self.pending = still

    def push_cell_output(self, name: str, mission: str) -> None:
        """The instant emitted `name`, an output to the cell: the command daemon publishes it."""
        self._send({"push": "cell_output", "name": name, "mission": mission})

    def _send(self, msg: dict[str, Any]) -> None:
        """A reply or a push to the command daemon, never blocking: after what waits for room
        on the link (`outbox`), in order; one that cannot wait (`OUTBOX_MAX`) is discarded,
        counted by kind and said (`_discard`)."""
        if self.conn is None:
            return
        data = json.dumps(msg, default=str).encode()
        kind = str(msg["push"]) if "push" in msg else "one_way_error" if one_way(msg.get("id")) else "reply"
        if not self.outbox:
            try:
                self.conn.send(data)
                return
            except BlockingIOError:
                pass
            except OSError:  # the link is gone: `_receive` sees it
                return
        if len(self.outbox) >= OUTBOX_MAX:
            self._discard_oldest()
        self.outbox.append(data)
        self.outbox_kinds.append(kind)

    def _flush(self) -> None:
        """What waits for room on the link, oldest first, while there is room; then, if messages
        were discarded since the command daemon was last told, their counts (`link_discarded`)."""
        conn = self.conn
        if conn is None:
            return
        while self.outbox:
            try:
                conn.send(self.outbox[0])
            except BlockingIOError:
                return
            except OSError:
                return
            self.outbox.popleft()
            self.outbox_kinds.popleft()
        total = sum(self.discarded.values())
        if total != self.discarded_told:
            with contextlib.suppress(OSError):
                conn.send(json.dumps({"push": "link_discarded", "counts": self.discarded}).encode())
                self.discarded_told = total

    def _discard_oldest(self) -> None:
        """Room for one more: the oldest push (its loss is counted by the command daemon too:
        an output's in `cell.outputs.lost`), else the oldest reply (its request times out)."""
        i = next((i for i, k in enumerate(self.outbox_kinds) if k not in ("reply", "one_way_error")), 0)
        kind = self.outbox_kinds[i]
        del self.outbox[i]
        del self.outbox_kinds[i]
        self.discarded[kind] = self.discarded.get(kind, 0) + 1
        now = time.monotonic()
        if now - self.discard_logged_s >= DISCARD_LOG_S:
            self.discard_logged_s = now
            log.error(
                "the link to the command daemon is full (%d messages waiting): a %s discarded; "
                "discarded so far: %s",
                len(self.outbox),
                kind,
                ", ".join(f"{k} {n}" for k, n in sorted(self.discarded.items())),
            )

    def urgent(self, req: Request) -> dict[str, Any]:
        """An abort or a stop from the urgent socket (never a Pending: both act at once)."""
        rid, reply = self.handle(req)
        return reply if isinstance(reply, dict) else {"id": rid, "ok": False, "error": "not served here"}

    def handle(self, req: Request) -> tuple[Any, dict[str, Any] | Pending]:
        """(request id, reply or Pending). Any failure becomes an error reply with the id."""
        rid, cmd, args = req
        if COMMANDS[cmd].where != "rt":
            return rid, {"id": rid, "ok": False, "error": f"not a command of the real-time process: {cmd!r}"}
        try:
            result: Result | Pending = self.machine.command(cmd, args)
            return rid, result if isinstance(result, Pending) else {"id": rid, "ok": True, "result": result}
        except CommandError as e:
            return rid, {"id": rid, "ok": False, "error": str(e)}
        except Exception as e:  # a bug must not take the automaton thread down
            log.exception("command %s failed", cmd)
            return rid, {"id": rid, "ok": False, "error": f"internal error: {type(e).__name__}: {e}"}
