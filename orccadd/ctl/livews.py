"""A Foxglove WebSocket server (protocol `foxglove.websocket.v1`) on 127.0.0.1 that serves only
the user who started it.

Foxglove's own SDK serves every client that reaches its port, and on a robot PC every local user
reaches 127.0.0.1: the live view then showed the arm's state to users holding no role on the
daemon, and to any web page the operator's browser had open (a WebSocket handshake from a foreign
`Origin` was accepted). This server refuses, before the WebSocket opens (HTTP 403):

- a peer whose TCP socket belongs to another user than ours (root excepted): the kernel's socket
  table (/proc/net/tcp) names the owner of the peer's end of a loopback connection, as identd did;
- a handshake whose `Origin` is not in `origins` (default: none, i.e. a native client such as
  Foxglove's desktop app, and Foxglove's own web app), so a page elsewhere cannot read it.

What it speaks (the protocol's server side, as far as a read-only live view needs): serverInfo,
advertise, subscribe/unsubscribe, binary Message Data (opcode 1). `log` may be called from any
thread; slow clients lose messages rather than hold anything up (`websockets.broadcast`).
"""

from __future__ import annotations

import asyncio
import json
import os
import struct
import threading
import time
from dataclasses import dataclass
from http import HTTPStatus
from pathlib import Path
from typing import Any

from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

SUBPROTOCOL = "foxglove.websocket.v1"
HOST = "127.0.0.1"  # never another address
FOXGLOVE_ORIGINS = ("https://app.foxglove.dev", "https://studio.foxglove.dev")
MESSAGE_DATA = 1
START_WAIT_S = 10.0


@dataclass(frozen=True)
class Channel:
    """One advertised channel: JSON messages with a JSON schema."""

    id: int
    topic: str
    schema_name: str
    schema: bytes

    def advertised(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "topic": self.topic,
            "encoding": "json",
            "schemaName": self.schema_name,
            "schema": self.schema.decode(),
            "schemaEncoding": "jsonschema",
        }


def tcp_peer_uid(local: tuple[str, int], remote: tuple[str, int]) -> int | None:
    """The owner (uid) of the socket at `remote` connected to `local` on this machine (IPv4),
    from the kernel's table; None if it is not there (gone, or not local)."""

    def hexaddr(addr: tuple[str, int]) -> str:
        packed = bytes(int(x) for x in addr[0].split("."))
        return f"{int.from_bytes(packed, 'little'):08X}:{addr[1]:04X}"

    want_local, want_remote = hexaddr(remote), hexaddr(local)  # the peer's view of the connection
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        cols = line.split()
        if len(cols) > 7 and cols[1] == want_local and cols[2] == want_remote:
            return int(cols[7])
    return None


class LiveServer:
    """The server in a thread of its own (an asyncio loop), channels fixed at construction."""

    def __init__(
        self,
        name: str,
        channels: list[Channel],
        port: int = 8765,
        origins: tuple[str, ...] = FOXGLOVE_ORIGINS,
        allowed_uids: tuple[int, ...] | None = None,
    ) -> None:
        self.name = name
        self.channels = {c.id: c for c in channels}
        self.origins = origins
        self.allowed_uids = allowed_uids if allowed_uids is not None else (os.getuid(), 0)
        self.subscriptions: dict[ServerConnection, dict[int, int]] = {}  # client → channel → sub id
        self.refused = 0  # handshakes refused (foreign user or origin)
        self.session_id = str(time.time_ns())
        self._loop = asyncio.new_event_loop()
        self._server: Server | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(port,), name="foxglove-ws", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_WAIT_S) or self._server is None:
            raise OSError(f"the WebSocket server did not start on {HOST}:{port}: {self._error}")

    @property
    def port(self) -> int:
        assert self._server is not None
        return int(next(iter(self._server.sockets)).getsockname()[1])

    # ---- any thread ---------------------------------------------------------------------------
    def log(self, channel_id: int, payload: bytes, log_time_ns: int) -> None:
        """Send one message to every client subscribed to the channel."""
        if not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._send, channel_id, payload, log_time_ns)

    def stop(self) -> None:
        """Close every connection and the listening socket; returns once they are closed."""
        if self._loop.is_closed() or not self._thread.is_alive():
            return
        asyncio.run_coroutine_threadsafe(self._close(), self._loop).result(timeout=START_WAIT_S)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=START_WAIT_S)

    # ---- the server's thread ------------------------------------------------------------------
    def _run(self, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(self._start(port))
        except BaseException as e:  # reported by the constructor
            self._error = e
            self._ready.set()
            self._loop.close()
            return
        self._ready.set()
        try:
            self._loop.run_forever()
        finally:
            self._loop.close()

    async def _start(self, port: int) -> Server:
        return await serve(
            self._serve,
            HOST,
            port,
            subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
            process_request=self._check_peer,
            origins=[None, *self.origins],  # type: ignore[list-item]
            max_size=1 << 16,
        )

    async def _close(self) -> None:
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()

    def _check_peer(self, conn: ServerConnection, request: Request) -> Response | None:
        local, remote = conn.local_address[:2], conn.remote_address[:2]
        uid = tcp_peer_uid(local, remote)
        if uid is None or uid not in self.allowed_uids:
            self.refused += 1
            who = "an unknown peer" if uid is None else f"uid {uid}"
            body = f"refused: {who}; this live view serves the user who started it only\n"
            return Response(HTTPStatus.FORBIDDEN, "Forbidden", Headers(), body.encode())
        return None

    async def _serve(self, ws: ServerConnection) -> None:
        if ws.subprotocol != SUBPROTOCOL:
            await ws.close(1002, f"this server speaks {SUBPROTOCOL} only")
            return
        info = {
            "op": "serverInfo",
            "name": self.name,
            "capabilities": [],
            "metadata": {},
            "sessionId": self.session_id,
        }
        await ws.send(json.dumps(info))
        await ws.send(
            json.dumps({"op": "advertise", "channels": [c.advertised() for c in self.channels.values()]})
        )
        subs = self.subscriptions[ws] = {}
        try:
            async for raw in ws:
                if isinstance(raw, str):
                    self._on_request(ws, subs, raw)
        except ConnectionClosed:
            pass
        finally:
            self.subscriptions.pop(ws, None)

    def _on_request(self, ws: ServerConnection, subs: dict[int, int], raw: str) -> None:
        try:
            msg = json.loads(raw)
        except ValueError:
            return
        if not isinstance(msg, dict):
            return
        if msg.get("op") == "subscribe":
            for s in msg.get("subscriptions", []):
                if not isinstance(s, dict) or s.get("channelId") not in self.channels:
                    continue
                sid = s.get("id")
                if isinstance(sid, int) and 0 <= sid < 2**32 and sid not in subs.values():
                    subs[s["channelId"]] = sid
        elif msg.get("op") == "unsubscribe":
            gone = set(msg.get("subscriptionIds", []))
            for ch, sid in list(subs.items()):
                if sid in gone:
                    del subs[ch]

    def _send(self, channel_id: int, payload: bytes, log_time_ns: int) -> None:
        for ws, subs in list(self.subscriptions.items()):
            sid = subs.get(channel_id)
            if sid is not None:
                frame = struct.pack("<BIQ", MESSAGE_DATA, sid, log_time_ns) + payload
                broadcast([ws], frame)
