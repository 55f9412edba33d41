"""The command daemon's one link to the real-time process: a SOCK_SEQPACKET socket, a datagram a
message. Every request goes through `RtLink`: `call` from the asyncio loop (each request its own
id, its reply handed back by one reader task, so a long `load` never holds up an `abort` sent
after it) and `send_oneway` from any thread (a peer's signal from Zenoh's). Nothing else writes
to the socket."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from orccadd.wire.commands import RT_REPLY_S

log = logging.getLogger("orccadd.cmdd")

RT_MAX = 1 << 20  # the largest message on the link (the real-time process's own bound)
LATE_MAX = 256  # requests given up on whose late replies are still recognised


class RtLink:
    """The SEQPACKET link to the real-time process. Requests go out as they come, each with its
    own id; one reader task hands each reply to the request it answers. So a long request (a
    `load` compiling for seconds) never holds up an `abort` sent after it."""

    def __init__(self, path: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET | socket.SOCK_CLOEXEC)
        self.sock.connect(path)
        self.sock.setblocking(False)
        self.send_lock = asyncio.Lock()
        self.waiting: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self.reader: asyncio.Task[None] | None = None
        self.next_id = 0
        self.closed = False
        self.on_push: Callable[[dict[str, Any]], None] = lambda msg: None  # unasked: `{"push": …}`
        self.oneway_id = 0  # requests whose reply nobody awaits: negative ids, counting down
        self._oneway_lock = threading.Lock()  # `send_oneway` is called from other threads
        # a one-way request refused (the real-time process replies to those only then)
        self.on_refused: Callable[[dict[str, Any]], None] = lambda reply: None
        self.discarded: dict[str, int] = {}  # what the real-time process dropped, its link full
        self.late: dict[int, tuple[str, float]] = {}  # requests given up on: (command, when)
        self.late_replies = 0

    async def _read_replies(self) -> None:
        loop = asyncio.get_running_loop()
        with contextlib.suppress(OSError):
            while True:
                data = await loop.sock_recv(self.sock, RT_MAX)
                if not data:
                    break
                try:
                    reply = json.loads(data)
                except ValueError:
                    continue
                if isinstance(reply, dict) and "push" in reply:
                    self._pushed(reply)
                    continue
                rid = reply.get("id") if isinstance(reply, dict) else None
                fut = self.waiting.pop(rid, None) if isinstance(rid, int) else None
                if fut is not None and not fut.done():
                    fut.set_result(reply)
                elif isinstance(rid, int) and rid < 0:
                    self.on_refused(reply)
                elif isinstance(rid, int) and rid in self.late:
                    self._late(rid, reply)
        self.closed = True
        for fut in self.waiting.values():
            if not fut.done():
                fut.set_result({"ok": False, "error": "the real-time process is gone"})
        self.waiting.clear()

    def _pushed(self, msg: dict[str, Any]) -> None:
        if msg.get("push") == "link_discarded" and isinstance(msg.get("counts"), dict):
            self.discarded = {str(k): int(v) for k, v in msg["counts"].items()}
            log.error(
                "the real-time process's link to this daemon was full: it discarded %s",
                ", ".join(f"{n} {k}" for k, n in sorted(self.discarded.items())),
            )
            return
        self.on_push(msg)

    def _late(self, rid: int, reply: dict[str, Any]) -> None:
        """A reply that came after its request was answered `NOT confirmed`: said, with what
        it says (the client was told the command may have been done)."""
        cmd, since = self.late.pop(rid)
        self.late_replies += 1
        log.warning(
            "the real-time process answered %s %.1f s after the wait ended (its client was told "
            "NOT confirmed): %s",
            cmd,
            time.monotonic() - since,
            "ok" if reply.get("ok") else f"error: {reply.get('error')}",
        )

    def report(self) -> dict[str, Any]:
        """For `status`'s `rt_link`: messages the real-time process discarded (its link full),
        by kind; replies that came after their wait ended."""
        return {"discarded": dict(self.discarded), "late_replies": self.late_replies}

    def send_oneway(self, cmd: str, args: dict[str, Any]) -> bool:
        """From any thread (a peer's signal from Zenoh's): `cmd` as a one-way request, a
        negative id the real-time process replies to only to refuse it (`on_refused`). Sent
        whole at once (one datagram) or not at all: False if the link's buffer is full or the
        link is gone."""
        if self.closed:
            return False
        with self._oneway_lock:  # each id once, on the link in the order of the ids
            rid = self.oneway_id - 1
            try:
                self.sock.send(json.dumps({"id": rid, "cmd": cmd, "args": args}).encode())
            except OSError:  # the buffer full (EAGAIN), or the link gone: the caller's queue then
                return False
            self.oneway_id = rid
        return True

    async def call(
        self, cmd: str, args: dict[str, Any], timeout_s: float | None = RT_REPLY_S
    ) -> dict[str, Any]:
        """The reply to `cmd`, or an error reply (no answer within `timeout_s`; None: until one
        comes or the link is lost)."""
        if self.closed:
            return {"ok": False, "error": "the real-time process is gone"}
        loop = asyncio.get_running_loop()
        if self.reader is None:
            self.reader = loop.create_task(self._read_replies())
        self.next_id += 1
        rid = self.next_id
        fut: asyncio.Future[dict[str, Any]] = loop.create_future()
        self.waiting[rid] = fut
        try:
            async with self.send_lock:  # one message at a time on the socket
                await loop.sock_sendall(self.sock, json.dumps({"id": rid, "cmd": cmd, "args": args}).encode())
            return await asyncio.wait_for(fut, timeout_s)
        except TimeoutError:
            # not a failure: the command may have been done, and its reply come later (`_late`)
            if len(self.late) >= LATE_MAX:
                self.late.pop(next(iter(self.late)))
            self.late[rid] = (cmd, time.monotonic())
            return {
                "ok": False,
                "error": f"{cmd} NOT confirmed: the real-time process did not answer within "
                f"{timeout_s:g} s; it may still have been done (`events` says)",
            }
        except OSError as e:
            self.closed = True
            return {"ok": False, "error": f"link to the real-time process lost: {e}"}
        finally:
            self.waiting.pop(rid, None)
