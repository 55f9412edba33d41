"""A userspace virtual CAN bus for kernels without SocketCAN, reachable by stock python-can.

It speaks the socketcand text protocol (github.com/linux-can/socketcand, "raw mode") on
127.0.0.1, so `can.Bus(interface="socketcand", host="127.0.0.1", port=PORT, channel="can0")`
connects to it exactly as it would to a socketcand host in front of a real bus:

    server: < hi >                  client: < open can0 >
    server: < ok >                  client: < rawmode >
    server: < ok >
    client: < send 123 2 de ad >    server: < frame 123 1700000000.000123 DEAD >  (to the others)

Each channel name is one bus. A frame a client sends goes to every other client on the same
channel, in the order the hub received it; the sender gets no echo; nothing is dropped (a client
that stops reading until its backlog passes `--max-backlog-bytes` is disconnected, loudly,
instead of silently losing frames for everyone). Frames reach a new client only after a short
hold-off following its `< ok >` to `rawmode` (kept, not lost), because python-can reads the
handshake replies with single `recv` calls that must not carry frames as well.

Run: `python -m orccadd.vcan [--port 0]`; it prints `virtual_can: listening on
127.0.0.1:PORT` once ready (`--port-file F` also writes PORT to F).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import signal
import socket
import time
from dataclasses import dataclass, field

from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.runtime.rt import fifo_priority

log = logging.getLogger("orccadd.vcan")

HOST = "127.0.0.1"
MAX_LINE = 256  # a socketcand command is short; more without a '>' is garbage
HOLD_OFF_S = 0.1
SNDBUF_BYTES = 256 * 1024


@dataclass
class Peer:
    writer: asyncio.StreamWriter
    name: str
    channel: str = ""
    raw: bool = False
    pending: list[bytes] = field(default_factory=list)  # frames held back during the hold-off
    ready: bool = False


class Hub:
    def __init__(self, max_backlog_bytes: int = 4 << 20, hold_off_s: float = HOLD_OFF_S) -> None:
        self.channels: dict[str, list[Peer]] = {}
        self.max_backlog = max_backlog_bytes
        self.hold_off_s = hold_off_s
        self.frames = 0
        self.clients: set[asyncio.Task[None]] = set()  # one per connection, to end them on stop

    async def close_clients(self) -> None:
        """End every connection's task (on stop), so that none is left to be cancelled by the
        event loop's shutdown (Python 3.11's stream callback then logs a CancelledError)."""
        for task in list(self.clients):
            task.cancel()
        await asyncio.gather(*self.clients, return_exceptions=True)

    # ---- one client -------------------------------------------------------------------------
    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sock = writer.get_extra_info("socket")
        if sock is not None:  # a fixed kernel queue per client: the backlog check sees the rest
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SNDBUF_BYTES)
        addr = writer.get_extra_info("peername")
        peer = Peer(writer, f"{addr[0]}:{addr[1]}" if addr else "?")
        task = asyncio.current_task()
        if task is not None:
            self.clients.add(task)
            task.add_done_callback(self.clients.discard)
        writer.write(b"< hi >")
        buf = b""
        try:
            while True:
                chunk = await reader.read(65536)
                if not chunk:
                    return
                buf += chunk
                out: dict[str, list[bytes]] = {}
                while True:
                    end = buf.find(b">")
                    if end < 0:
                        if len(buf) > MAX_LINE:
                            self._say(f"{peer.name}: {len(buf)} bytes without '>': dropped the connection")
                            return
                        break
                    cmd, buf = buf[: end + 1].strip(), buf[end + 1 :]
                    frame = self._command(peer, cmd)
                    if frame is not None:
                        out.setdefault(peer.channel, []).append(frame)
                for channel, frames in out.items():
                    self._broadcast(peer, channel, b"".join(frames), len(frames))
        except (ConnectionError, asyncio.IncompleteReadError):
            return
        except asyncio.CancelledError:  # the hub stops (`close_clients`): this connection ends
            return
        finally:
            self._leave(peer)
            writer.close()
            with contextlib.suppress(ConnectionError, OSError):
                await writer.wait_closed()

    def _command(self, peer: Peer, cmd: bytes) -> bytes | None:
        """Apply one `< ... >` command; a frame to forward (already encoded) for `send`."""
        parts = cmd.decode("ascii", "replace").split()
        if len(parts) < 2 or parts[0] != "<" or parts[-1] != ">":
            self._say(f"{peer.name}: not a socketcand command: {cmd[:60]!r}")
            return None
        word, args = parts[1], parts[2:-1]
        if word == "open" and len(args) == 1 and not peer.channel:
            peer.channel = args[0]
            self.channels.setdefault(peer.channel, []).append(peer)
            peer.writer.write(b"< ok >")
        elif word == "rawmode" and peer.channel:
            peer.raw = True
            peer.writer.write(b"< ok >")
            asyncio.get_running_loop().call_later(self.hold_off_s, self._release, peer)
        elif word == "send" and peer.raw:
            return self._encode(peer, args)
        elif word == "echo":
            peer.writer.write(b"< echo >")
        else:
            self._say(f"{peer.name}: unsupported or out-of-order command {' '.join(parts)!r}: ignored")
        return None

    def _encode(self, peer: Peer, args: list[str]) -> bytes | None:
        """`send ID LEN B0 B1 ...` -> `< frame ID SEC.USEC DATA >`."""
        try:
            can_id, length = int(args[0], 16), int(args[1], 16)
            data = bytes(int(b, 16) for b in args[2:])
            if len(data) != length or length > 8 or len(args[0]) not in (3, 8):
                raise ValueError
        except (ValueError, IndexError):
            self._say(f"{peer.name}: bad frame {' '.join(args)!r}: ignored")
            return None
        ident = f"{can_id & 0x7FF:03X}" if len(args[0]) == 3 else f"{can_id & 0x1FFFFFFF:08X}"
        self.frames += 1
        return f"< frame {ident} {time.time():.6f} {data.hex().upper()} >".encode()

    def _broadcast(self, sender: Peer, channel: str, payload: bytes, n: int) -> None:
        for p in list(self.channels.get(channel, ())):
            if p is sender or not p.raw:
                continue
            if not p.ready:
                p.pending.append(payload)
                continue
            transport = p.writer.transport
            if transport.get_write_buffer_size() > self.max_backlog:
                self._say(
                    f"{p.name} on {channel}: not reading ({self.max_backlog} bytes queued): disconnected"
                )
                self._leave(p)
                transport.abort()
                continue
            p.writer.write(payload)

    def _release(self, peer: Peer) -> None:
        peer.ready = True
        if peer.pending and not peer.writer.is_closing():
            peer.writer.write(b"".join(peer.pending))
        peer.pending.clear()

    def _leave(self, peer: Peer) -> None:
        members = self.channels.get(peer.channel, [])
        if peer in members:
            members.remove(peer)

    @staticmethod
    def _say(msg: str) -> None:
        log.warning("%s", msg)


async def run(port: int, port_file: str, max_backlog: int) -> None:
    hub = Hub(max_backlog)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    server = await asyncio.start_server(hub.serve, HOST, port, limit=1 << 20)
    bound = server.sockets[0].getsockname()[1]  # asyncio sets TCP_NODELAY on each connection
    if port_file:
        tmp = f"{port_file}.tmp"
        with open(tmp, "w") as fh:
            fh.write(f"{bound}\n")
        os.replace(tmp, port_file)
    print(f"orccadd.vcan: listening on {HOST}:{bound}", flush=True)
    async with server:
        await stop.wait()
        await hub.close_clients()
    log.info("stopped after %d frames", hub.frames)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m orccadd.vcan",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--port", type=int, default=29536, help="TCP port on 127.0.0.1 (0: any free port)")
    ap.add_argument("--port-file", default="", help="also write the port to this file when ready")
    ap.add_argument("--max-backlog-bytes", type=int, default=4 << 20)
    ap.add_argument(
        "--priority", type=int, default=0, help="SCHED_FIFO priority (a bus has no load); 0: normal"
    )
    args = ap.parse_args(argv)
    try:
        setup_logging("orccadd.vcan")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    if fifo_priority(args.priority):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
        except OSError as e:
            log.warning("SCHED_FIFO %d refused (%s): normal priority", args.priority, e.strerror)
    try:
        asyncio.run(run(args.port, args.port_file, args.max_backlog_bytes))
    except OSError as e:
        log.error("cannot listen on %s:%d: %s", HOST, args.port, e.strerror or e)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
