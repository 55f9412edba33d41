"""The companion command daemon (after seed 001's target daemon): the only process clients talk to.

It serves orccadctl over the public Unix socket (asyncio, bounded: clients, line length, one
request at a time per client), checks every request (protocol, then the peer's role from
SO_PEERCRED), forwards what the real-time process must do over the SEQPACKET link, and serves
status, monitor, events and logs from shared memory without asking it. If it dies, the mission
goes on (or safe-stops, by config) and the real-time process starts a new one.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import pwd
import signal
import socket
import stat
import sys
import time
from pathlib import Path
from typing import Any

from orccadd.cmdd import logfetch, views
from orccadd.cmdd.cellplug import CellPlugin
from orccadd.cmdd.csvlog import LogDir
from orccadd.cmdd.logsession import LogSource, TelemetryLog, mission_record
from orccadd.cmdd.rtlink import RtLink
from orccadd.cmdd.urdf import urdf_path
from orccadd.config.cellnet import CellNetConfig
from orccadd.config.robot import DaemonConfig
from orccadd.config.station import read_station_config
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.wire.commands import (
    COMMANDS,
    LOG_SIGNALS,
    MAX_LINE,
    RT_REPLY_S,
    URGENT_COMMANDS,
    Dispatcher,
    ProtocolError,
    Role,
    encode,
    error_reply,
    handles,
    parse_request,
    with_defaults,
)
from orccadd.wire.roles import Roles, peer_credentials
from orccadd.wire.schema import PROTOCOL_VERSION, H, MissionResult, S
from orccadd.wire.socketdir import SocketPathError, bind_with_mode, prepare_socket_dir
from orccadd.wire.telemetry import RingReader, TelemetryBlock, read_status

log = logging.getLogger("orccadd.cmdd")
NICE = -10
MONITOR_MIN_HZ = 0.01

ROLELESS_MAX = 8  # peers without a role waited for at once (each gets one refusal)
ROLELESS_WAIT_S = 2.0
# beyond `control_clients`, a control peer may still send one abort or stop: so many are waited
# for at once (a newer one closes the oldest), each for its first line this long
RESERVED_MAX = 4
RESERVED_WAIT_S = 2.0
CELL_SWITCH_INTERVAL_S = 0.0005  # with a cell: Zenoh's threads get the GIL this soon


class ClientReader(asyncio.StreamReader):
    """A client's stream reader that says, as an event to wait on, when the client's end has
    closed (or the daemon is stopping): a stream that writes nothing for a while must still not
    keep a slot for nobody."""

    def __init__(self, limit: int) -> None:
        super().__init__(limit=limit)
        self.ended = asyncio.Event()

    def feed_eof(self) -> None:
        super().feed_eof()
        self.ended.set()

    def set_exception(self, exc: Exception) -> None:
        super().set_exception(exc)
        self.ended.set()


class CommandDaemon:
    def __init__(
        self,
        cfg: DaemonConfig,
        socket_path: str,
        rt_path: str,
        telemetry: str,
        log_dir: Path | None = None,
        urdf: Path | None = None,
        net: CellNetConfig | None = None,
    ) -> None:
        self.cfg = cfg
        self.net = net  # `[cell]`: a peer of a cell of PCs over Zenoh
        self.cell: CellPlugin | None = None  # its part in the cell (`cellplug`), once joined
        self.socket_path = socket_path
        self.log_dir = log_dir or Path(socket_path).parent / "logs"
        self.logs = LogDir(self.log_dir, cfg.socket_group)
        self.urdf = urdf  # attached to each log's MCAP
        self.rt = RtLink(rt_path)
        self.block = TelemetryBlock.attach(telemetry)  # the daemon's own: status, trace, its pid
        self.unit_tels: dict[str, TelemetryBlock] = {}  # each resource's, by block name (`describe`)
        self.roles = Roles(cfg)
        self.desc: dict[str, Any] = {}
        self.desc_mark = (0, 0)  # (mission generation, safe stop number) `desc` was read at
        self.missions: dict[int, dict[str, Any]] = {}  # generation → mission: names the trace
        self.slots = {Role.CONTROL: 0, Role.READ: 0}  # connections served, per role
        self.roleless = 0
        self.reserved: list[asyncio.StreamWriter] = []  # control peers beyond the limit, oldest first
        self.recording: TelemetryLog | None = None
        self.last_log: dict[str, Any] | None = None
        self.server: asyncio.AbstractServer | None = None
        self.done = asyncio.Event()
        self.sock_ino = 0
        self.dispatch = Dispatcher(self, "cmdd")
        self.readers: dict[asyncio.StreamWriter, ClientReader] = {}  # for streams: gone?

    async def refresh(self, timeout_s: float | None = RT_REPLY_S) -> None:
        st = read_status(self.block)
        mark = (int(st[S.MISSION_GEN]), int(st[S.FAULTED]))
        if not self.desc or mark != self.desc_mark:  # a new mission, a new fault, or one cleared
            reply = await self.rt.call("describe", {}, timeout_s)
            if reply.get("ok"):
                self.desc = reply["result"]
                self.desc_mark = mark
                self.missions = {int(m["generation"]): m for m in self.desc.get("missions", [])}
                self._attach_units()
                if self.cell is not None:  # the inputs it takes from the cell, its outputs to it
                    self.cell.peer.mission_changed(self.desc.get("mission"))

    def _attach_units(self) -> None:
        """Each resource's telemetry block (its ticks), once."""
        for r in self.desc.get("resources", []):
            name = r.get("telemetry", "")
            if name and name not in self.unit_tels:
                try:
                    self.unit_tels[name] = TelemetryBlock.attach(name)
                except (OSError, ValueError) as e:
                    log.warning("resource %s: its telemetry block %s: %s", r.get("name"), name, e)

    def units(self) -> list[tuple[dict[str, Any], TelemetryBlock]]:
        """A station's resources with their telemetry blocks (none for a one-resource robot: its
        signals, streams and logs are named without it)."""
        found = [(r, self.unit_tels.get(r.get("telemetry", ""))) for r in self.desc.get("resources", [])]
        if len(found) < 2:
            return []
        return [(r, t) for r, t in found if t is not None]

    @property
    def tel(self) -> TelemetryBlock:
        """The telemetry block of the resource a client addresses when it names none (the one
        resource, or the first listed: `describe`'s top-level `telemetry`)."""
        return self.unit_tels[str(self.desc["telemetry"])]

    def _sources(self, names: list[str]) -> list[LogSource]:
        """What `monitor` and `log` sample: in a station each resource's signals from its own block,
        labelled by it (`left/q.0`); else the one resource's. `ValueError` naming a signal no
        resource has."""
        units = self.units()
        if not units:
            own = (self.desc.get("resource") or {}).get("tick_signals", [])
            return [
                LogSource("", self.tel, views.SignalSelection(names, self.desc.get("joints", []), "", own))
            ]
        signals = {str(r["name"]): (r.get("description") or {}).get("tick_signals", []) for r, _ in units}
        sels = views.cell_selections(names, [(str(r["name"]), list(r["joints"])) for r, _ in units], signals)
        return [LogSource(str(r["name"]), tel, sels[r["name"]]) for r, tel in units if r["name"] in sels]

    def decode_trace(self, rec: Any) -> dict[str, Any]:
        return views.decode_trace(rec, self.desc, self.missions)

    # ---- socket ---------------------------------------------------------------------------
    def _prepare_socket(self) -> socket.socket:
        path = Path(self.socket_path)
        try:
            gid = prepare_socket_dir(path.parent, self.cfg.socket_group)  # checked, never changed
        except SocketPathError as e:
            raise SystemExit(f"orccadd-cmdd: {e}") from None
        with contextlib.suppress(FileNotFoundError):
            if stat.S_ISSOCK(os.lstat(path).st_mode):
                os.unlink(path)
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        bind_with_mode(s, path, 0o117)
        if gid >= 0:
            os.chown(path, -1, gid)
        self.sock_ino = os.stat(path).st_ino
        return s

    async def serve(self) -> None:
        # the real-time process starts this one while its arm is being configured, and answers
        # once it is held: the public socket is bound only then, so that no client ever reaches
        # a daemon that cannot answer yet (a start that fails ends this process, or the link)
        await self.refresh(timeout_s=None)
        if self.rt.closed:
            log.info("the real-time process is gone before serving; exiting")
            return
        sock = self._prepare_socket()
        loop = asyncio.get_running_loop()
        self.server = await loop.create_unix_server(
            lambda: asyncio.StreamReaderProtocol(ClientReader(MAX_LINE), self._client), sock=sock
        )
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, self.done.set)
        self._resume_log()
        pump = asyncio.create_task(self._pump())
        if self.net is not None:
            self.cell = await CellPlugin.join(self, self.net)
        await self.done.wait()
        if self.cell is not None:
            self.cell.close()
        for reader in self.readers.values():  # streams end now
            reader.ended.set()
        pump.cancel()
        self.server.close()
        if self.recording is not None:
            with contextlib.suppress(OSError):
                self.recording.close("the command daemon stopped")
            if not _alive(int(self.block.header[H.PID])):
                self.logs.clear_state()  # the daemon stopped; else a successor carries the log on
        with contextlib.suppress(FileNotFoundError):
            if os.stat(self.socket_path).st_ino == self.sock_ino:
                os.unlink(self.socket_path)

    async def _pump(self) -> None:
        """Background: follow the log, notice the real-time process going away."""
        while True:
            await asyncio.sleep(0.05)
            if self.recording is not None:
                await self.refresh()  # the names of a new mission's events
            if self.recording is not None:
                await self._record_mission(self.recording)  # a mission loaded meanwhile
            if self.recording is not None:
                try:
                    self.recording.pump()
                except OSError as e:
                    self._end_log(self.recording.abandon(e))
            if self.recording is not None and self.recording.size_bytes() > self.cfg.log_max_mb * 1e6:
                limit = f"its size limit, {self.cfg.log_max_mb:g} MB (daemon.log_max_mb)"
                try:
                    summary = self.recording.close(f"reached {limit}")
                    self._end_log(
                        {**summary, "error": f"log ended: reached {limit} after {summary['rows']} rows"}
                    )
                except OSError as e:
                    self._end_log(self.recording.abandon(e))
            if self.rt.closed or not _alive(int(self.block.header[H.PID])):
                log.info("the real-time process is gone; exiting")
                self.done.set()
                return

    # ---- clients --------------------------------------------------------------------------
    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sock = writer.get_extra_info("socket")
        _, uid, gid = peer_credentials(sock)
        role = self.roles.role(uid, gid)
        try:
            if role is None:
                await self._refuse_roleless(reader, writer, uid)
                return
            limit = self.cfg.control_clients if role is Role.CONTROL else self.cfg.read_clients
            if self.slots[role] >= limit and role is Role.CONTROL:
                await self._serve_reserved(reader, writer, uid, limit)
                return
            if self.slots[role] >= limit:
                writer.write(
                    encode(error_reply(None, f"too many clients with the {role} role (max {limit})"))
                )
                await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)
                return
            self.slots[role] += 1
            assert isinstance(reader, ClientReader)
            self.readers[writer] = reader
            try:
                await self._serve_client(reader, writer, role, uid)
            finally:
                self.slots[role] -= 1
                self.readers.pop(writer, None)
        except (ConnectionError, BrokenPipeError, TimeoutError):
            return
        except asyncio.CancelledError:  # the daemon is stopping: the connection just ends
            return
        finally:
            with contextlib.suppress(Exception):
                if writer.transport.get_write_buffer_size():
                    writer.transport.abort()  # a client not reading: no waiting for it
                else:
                    writer.close()

    async def _serve_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, role: Role, uid: int
    ) -> None:
        idle = self.cfg.idle_timeout_s
        while True:
            try:
                line = await asyncio.wait_for(reader.readuntil(b"\n"), idle)
            except asyncio.IncompleteReadError:
                return
            except TimeoutError:
                writer.write(
                    encode(error_reply(None, f"no request for {idle:g} s: closing (idle_timeout_s)"))
                )
                await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)
                return
            except asyncio.LimitOverrunError:
                writer.write(encode(error_reply(None, f"request longer than {MAX_LINE} bytes")))
                await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)
                return  # the stream cannot be resynchronised: close
            await self._request(line, role, uid, writer)

    async def _serve_reserved(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, uid: int, limit: int
    ) -> None:
        """Every control place is taken (by busy or idle clients, or by someone holding them):
        an abort or a stop is still served, on this one connection, then it is closed; any other
        request is refused. At most `RESERVED_MAX` such peers are waited for at once, for
        `RESERVED_WAIT_S` each; a newer one closes the oldest, so they cannot be held either."""
        if len(self.reserved) >= RESERVED_MAX:
            self.reserved.pop(0).transport.abort()
        self.reserved.append(writer)
        rid: Any = None
        cmd = ""
        try:
            line = await asyncio.wait_for(reader.readuntil(b"\n"), RESERVED_WAIT_S)
            rid, cmd, _ = parse_request(line)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError, ConnectionError):
            line = b""
        except ProtocolError as e:
            rid = e.rid
        finally:
            if writer in self.reserved:
                self.reserved.remove(writer)
        if writer.transport.is_closing():
            return
        if cmd in URGENT_COMMANDS:
            await self._request(line, Role.CONTROL, uid, writer)
            return
        why = f"too many clients with the control role (max {limit}; beyond that only abort and stop)"
        writer.write(encode(error_reply(rid, why)))
        await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)

    async def _refuse_roleless(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, uid: int
    ) -> None:
        """A peer without any role gets one refusal (to its first request, if it sends one soon)
        and the connection is closed; at most a few such peers are waited for at once."""
        rid: Any = None
        if self.roleless < ROLELESS_MAX:
            self.roleless += 1
            try:
                line = await asyncio.wait_for(reader.readuntil(b"\n"), ROLELESS_WAIT_S)
                with contextlib.suppress(ProtocolError):
                    rid = parse_request(line)[0]
            except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError):
                pass
            finally:
                self.roleless -= 1
        writer.write(
            encode(error_reply(rid, f"not authorised: user {_user(uid)} holds no role on this daemon"))
        )
        await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)

    async def _request(self, line: bytes, role: Role | None, uid: int, writer: asyncio.StreamWriter) -> None:
        reply = await self.answer(line, role, f"user {_user(uid)}", writer)
        if reply:
            writer.write(encode(reply))
        await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)

    async def answer(
        self, line: bytes, role: Role | None, who: str, writer: asyncio.StreamWriter | None = None
    ) -> dict[str, Any]:
        """The reply to one request line from `who` with `role`: the socket's clients and the
        cell's peers (`writer` None: no stream) go through the same checks and the same table."""
        rid: Any = None
        try:
            rid, cmd, args = parse_request(line)
        except ProtocolError as e:
            return error_reply(e.rid, str(e))
        spec = COMMANDS[cmd]
        if spec.role is Role.CELL:
            return error_reply(
                rid, f"{cmd!r} is the command daemon's own: a peer's signal comes over the cell"
            )
        if role is None or (spec.role is Role.CONTROL and role is not Role.CONTROL):
            need = "the control role" if spec.role is Role.CONTROL else "the read-only role"
            return error_reply(rid, f"not authorised: {who} lacks {need} for {cmd!r}")
        if cmd == "deploy":  # who deploys is the peer this daemon knows, never what it says
            args = {**args, "by": who}
        if spec.where == "rt":
            reply = await self.rt.call(cmd, args, spec.reply_s)
            reply["id"] = rid
            if spec.loads and reply.get("ok"):
                await self.refresh()
            return reply
        if writer is None and (cmd == "monitor" or (cmd == "events" and args.get("follow"))):
            return error_reply(
                rid,
                f"{cmd}: streams are served on the daemon's socket only (from the cell: `orccadctl cell`)",
            )
        try:
            result = await self.dispatch.handler(cmd)(writer, rid, **with_defaults(spec, args))
            return {"id": rid, "ok": True, "result": result}
        except ValueError as e:
            return error_reply(rid, str(e))
        except (ConnectionError, TimeoutError, asyncio.CancelledError):
            raise
        except Exception as e:  # a bug must not take the command daemon down
            log.exception("%s failed: %s: %s", cmd, type(e).__name__, e)
            return error_reply(rid, f"internal error: {type(e).__name__}: {e}")

    # ---- local commands -------------------------------------------------------------------
    @handles("ping")
    async def do_ping(self, writer: asyncio.StreamWriter, rid: Any) -> dict[str, Any]:
        return {"pong": True, "pid": os.getpid(), "protocol_version": PROTOCOL_VERSION}

    @handles("status")
    async def do_status(self, writer: asyncio.StreamWriter, rid: Any) -> dict[str, Any]:
        await self.refresh()
        return self.status_of(self.log_state())

    def log_state(self) -> dict[str, Any] | None:
        """The log being written, or the last one (None: none since the start)."""
        return self.recording.describe() if self.recording else self.last_log

    def status_of(self, log_state: dict[str, Any] | None) -> dict[str, Any]:
        """`status`'s result; with a cell, its `cell` section (what was dropped, and why)."""
        out = views.status(self.block, self.tel, self.desc, log_state, self.units())
        out["rt_link"] = self.rt.report()
        if self.cell is not None:
            out["cell"] = self.cell.peer.report()
        return out

    @handles("monitor")
    async def do_monitor(
        self,
        writer: asyncio.StreamWriter,
        rid: Any,
        signals: list[Any] | None,
        rate_hz: float,
        count: int,
        duration_s: float,
    ) -> dict[str, Any]:
        await self.refresh()
        if not all(isinstance(s, str) for s in signals or []):
            raise ValueError("monitor: signals must be a list of names")
        picks = [(s.tel, s.selection) for s in self._sources([str(s) for s in signals or []])]
        labels = [label for _, sel in picks for label in sel.labels]
        max_rate = 1.0 / min(tel.period_s for tel, _ in picks)
        if not MONITOR_MIN_HZ <= rate_hz <= max_rate:
            raise ValueError(
                f"monitor: rate_hz (={rate_hz}) must be in [{MONITOR_MIN_HZ:g}, {max_rate:g}] (the loop rate)"
            )
        if count < 0 or duration_s < 0:
            raise ValueError("monitor: count and duration_s must be positive")
        sent = 0
        t_end = time.monotonic() + duration_s if duration_s else float("inf")
        writer.write(encode({"id": rid, "ok": True, "stream": {"signals": ["t_s", *labels]}}))
        period = 1.0 / rate_hz
        nxt = time.monotonic()
        while time.monotonic() < t_end and not self.done.is_set():
            recs = [views.latest_tick(tel) for tel, _ in picks]
            ready = [rec for rec in recs if rec is not None]
            if len(ready) == len(recs):
                values = [v for rec, (_, sel) in zip(ready, picks, strict=True) for v in sel.values(rec)]
                t_s = ready[0][1]
                writer.write(encode({"id": rid, "ok": True, "stream": {"t_s": t_s, "values": values}}))
                await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)
                sent += 1
            if count and sent >= count:
                break
            nxt += period
            if not await self._wait_while_connected(writer, min(nxt, t_end) - time.monotonic()):
                break
        return {"samples": sent}

    async def _wait_while_connected(self, writer: asyncio.StreamWriter, seconds: float) -> bool:
        """Wait `seconds`; False as soon as the client has gone (its end closed: a stream must not
        keep a slot for nobody) or the daemon is stopping."""
        reader = self.readers.get(writer)
        if reader is None or reader.ended.is_set() or self.done.is_set() or writer.transport.is_closing():
            return False
        try:
            await asyncio.wait_for(reader.ended.wait(), max(0.0, seconds))
        except TimeoutError:
            return not writer.transport.is_closing()
        return False

    @handles("events")
    async def do_events(
        self,
        writer: asyncio.StreamWriter,
        rid: Any,
        last: int,
        follow: bool,
        duration_s: float,
    ) -> dict[str, Any]:
        await self.refresh()
        if not 0 <= last <= 100_000:
            raise ValueError("events: last must be in [0, 100000]")
        r = RingReader(self.block.trace, self.block.header, H.TRACE_HEAD, from_now=False)
        recs: Any = r.poll()[-last:] if last else []
        out = [self.decode_trace(rec) for rec in recs]
        if not follow:
            return {"events": out, "lost": r.lost}
        for e in out:
            writer.write(encode({"id": rid, "ok": True, "stream": e}))
        t_end = time.monotonic() + duration_s if duration_s else float("inf")
        while time.monotonic() < t_end and await self._wait_while_connected(writer, 0.05):
            new = r.poll()
            if len(new):
                await self.refresh()
            for rec in new:
                writer.write(encode({"id": rid, "ok": True, "stream": self.decode_trace(rec)}))
            await asyncio.wait_for(writer.drain(), self.cfg.stall_timeout_s)
        return {"lost": r.lost}

    @handles("log")
    async def do_log(
        self,
        writer: asyncio.StreamWriter,
        rid: Any,
        action: str,
        signals: list[Any] | None,
        name: str,
    ) -> dict[str, Any]:
        if action == "start":
            if self.recording is not None:
                raise ValueError(f"log: already logging to {self.recording.path} (log stop first)")
            await self.refresh()
            sources = self._sources([str(s) for s in signals or self._log_signals()])
            name = name or f"orccadd-{time.strftime('%Y%m%d-%H%M%S')}.csv"
            extra = {"rt_pid": int(self.block.header[H.PID])}
            rec = TelemetryLog.start(
                self.logs, sources, self.block, name, lambda: self.desc, self.decode_trace, self.urdf, extra
            )
            self.recording = rec
            await self._record_mission(rec)
            self.logs.save_state(rec.state)
            return rec.describe()
        if self.recording is None:
            raise ValueError("log: not logging")
        try:
            result = MissionResult(int(read_status(self.block)[S.RESULT])).name.lower()
            self._end_log(self.recording.close(result=result))
        except OSError as e:
            self._end_log(self.recording.abandon(e))
        return self.last_log or {}

    def _log_signals(self) -> list[str]:
        """What a log records when no signal is named: `LOG_SIGNALS`, and a one-resource robot's
        own signals (a UR's wrench, a camera's features: what a task may read besides q, dq, tau)."""
        if self.units():
            return list(LOG_SIGNALS)
        own = (self.desc.get("resource") or {}).get("tick_signals", [])
        return [*LOG_SIGNALS, *(str(g["name"]) for g in own)]

    async def _record_mission(self, rec: TelemetryLog) -> None:
        """The loaded mission into the log (`mission_record`), if it is not the one recorded last:
        at the log's start, and after each load while it runs."""
        gen = int(self.desc.get("generation", -1))
        if not self.desc.get("mission") or gen == rec.mission_generation:
            return
        from_tick = int(self.tel.header[H.TICK_HEAD]) + 1
        reply = await self.rt.call("params", {"task": ""})
        params = reply["result"].get("params", {}) if reply.get("ok") else {}
        values = {task: {p["name"]: p["value"] for p in ps} for task, ps in params.items()}
        try:
            rec.add_mission(mission_record(self.desc, values, from_tick))
            self.logs.save_state(rec.state)
        except (OSError, SocketPathError) as e:
            log.error("log %s: the mission's record not written: %s", rec.path, e)

    @handles("logs")
    async def do_logs(self, writer: asyncio.StreamWriter, rid: Any) -> dict[str, Any]:
        logs = await asyncio.to_thread(logfetch.list_logs, self.log_dir, self._writing())
        return {"directory": str(self.log_dir), "logs": logs}

    @handles("fetch")
    async def do_fetch(
        self, writer: asyncio.StreamWriter, rid: Any, name: str, offset: int, length: int
    ) -> dict[str, Any]:
        return await logfetch.read_chunk(self.log_dir, name, offset, length, self._writing())

    def _writing(self) -> str:
        """The CSV being written ("" when not logging)."""
        return self.recording.path.name if self.recording is not None else ""

    def _end_log(self, summary: dict[str, Any]) -> None:
        if "error" in summary:
            log.error("%s: %s", summary["file"], summary["error"])
        self.last_log = summary
        self.recording = None
        self.logs.clear_state()

    def _resume_log(self) -> None:
        """Carry on the log a command daemon before this one had open for this real-time process."""
        state = self.logs.load_state()
        if state is None:
            return
        if state.get("rt_pid") != int(self.block.header[H.PID]):
            log.info("log %s was open when the previous daemon stopped; left as it is", state.get("file"))
            self.logs.clear_state()
            return
        try:
            blocks = {str(r["name"]): (t, list(r["joints"])) for r, t in self.units()}
            blocks[""] = (self.tel, list(self.desc.get("joints", [])))
            rec = TelemetryLog.resume(
                self.logs, blocks, self.block, state, lambda: self.desc, self.decode_trace, self.urdf
            )
        except (OSError, SocketPathError, ValueError, KeyError, TypeError) as e:
            log.error("cannot carry on log %s: %s", state.get("file"), e)
            self.logs.clear_state()
            return
        self.recording = rec
        try:
            self.logs.save_state(rec.state)  # its new MCAP part
        except (OSError, SocketPathError) as e:
            log.error("log %s: cannot update the state file: %s", rec.path, e)
        log.info("carrying on log %s after %d rows; %s", rec.path, rec.rows, "; ".join(rec.notes))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def _above_clients() -> None:
    """Run at `NICE` (time-shared, not real time): clients at the default nice 0, however many and
    however busy, cannot starve the path of an operator's abort through this process."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, NICE)
    except PermissionError:
        now = os.getpriority(os.PRIO_PROCESS, 0)
        log.info("running at nice %d (not %d: needs CAP_SYS_NICE or LimitNICE=-10)", now, NICE)


def _user(uid: int) -> str:
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return str(uid)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="orccadd-cmdd", description="the orccadd command daemon")
    ap.add_argument("--config", required=True)
    ap.add_argument("--socket", required=True)
    ap.add_argument("--rt-socket", required=True)
    ap.add_argument("--telemetry", required=True, help="the real-time process's shared-memory block")
    args = ap.parse_args(argv)
    try:
        setup_logging("orccadd.cmdd")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    _above_clients()
    station = read_station_config(args.config)
    if station.cell is not None:  # a peer's signal waits for the GIL in Zenoh's thread: not 5 ms
        sys.setswitchinterval(CELL_SWITCH_INTERVAL_S)
    log_dir = station.resolve(station.daemon.log_dir) if station.daemon.log_dir else None
    try:
        d = CommandDaemon(
            station.daemon,
            args.socket,
            args.rt_socket,
            args.telemetry,
            log_dir,
            urdf_path(station.resources[0]),
            station.cell,
        )
    except (OSError, ValueError) as e:
        log.error("cannot attach to the real-time process: %s", e)
        return 2
    asyncio.run(d.serve())
    return 0
