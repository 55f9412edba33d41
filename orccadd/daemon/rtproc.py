"""`orccadd`: the real-time process.

Real-time threads where permitted, and nothing else:

- a control thread per resource, its clock domain (SCHED_FIFO `control_priority`): it ticks the
  resource's active Robot-Task every period of that resource, on the resource's clock (our own
  deadlines, or the device's cycle); it belongs to the resource's unit (`daemon.unit`), which
  owns it and the resource's other threads, and whatever ends it is that resource's fault;
- the main thread is the automaton thread (SCHED_FIFO `automaton_priority`, above the control
  threads): it sleeps in `poll()` on the control threads' event pipe, the command daemon's
  connection, signals and the command daemon's pidfd, and reacts.

Commands arrive from the companion command daemon (`orccadd.cmdd`, a separate process this one
spawns and respawns) over a SOCK_SEQPACKET socket whose kernel buffer is the bounded command
queue; replies are sent without blocking. Telemetry leaves through shared memory only.
SIGTERM/SIGINT: safe stop first, then the hardware is released.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import select
import signal
import socket
import subprocess
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

from orccadd.config.cell import CellConfig
from orccadd.config.shipped import list_configs, robot_config_path
from orccadd.daemon.machine import Machine
from orccadd.daemon.notify import Notifier
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.daemon.urgent import UrgentSocket
from orccadd.errors import OrccaddError, ResourceError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.physres import backend_class
from orccadd.physres.base import PhysicalResource
from orccadd.robot import create_resource, load_cell_config, simulated, with_backend
from orccadd.runtime import enter_realtime, leave_realtime
from orccadd.runtime.rt import RealtimeReport, lock_memory_early
from orccadd.runtime.threads import ThreadGroup, threads_left
from orccadd.task import load_task_file
from orccadd.task.loop import resource_clock
from orccadd.types import CommandMode, Status
from orccadd.wire.commands import COMMANDS, URGENT_COMMANDS, ProtocolError, parse_request
from orccadd.wire.schema import Layout, MachineState, MissionResult, OperatorAction, Trace
from orccadd.wire.socketdir import check_socket_path, prepare_socket_dir, urgent_socket_path
from orccadd.wire.telemetry import TelemetryBlock
from orccadd.wire.version import version_text

log = logging.getLogger("orccadd")

RT_MAX = 1 << 20  # largest message on the link to the command daemon (it refuses larger)
TICK_RING_S = 16.0  # seconds of ticks the telemetry ring keeps
RESPAWN_DELAY_S = 1.0
RESPAWN_MAX_S = 60.0
RESPAWN_STABLE_S = 10.0  # a command daemon that lived this long had started fine
GIL_SWITCH_INTERVAL_S = 0.0002
JOIN_S = 2.0  # how long shutdown waits for a thread (one stuck in a device call is named, then left)
RELEASE_S = 8.0  # how long shutdown waits for the resources' release (one that hangs: named, then left)
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


class RealtimeProcess:
    def __init__(self, cell: CellConfig, socket_path: str, args: argparse.Namespace) -> None:
        self.cell = cell
        self.args = args
        self.socket_path = socket_path
        self.rt_path = rt_socket_path(socket_path)
        self.notifier = Notifier()
        self.resources = [create_resource(cfg) for cfg in cell.resources]
        spin_s = args.spin_us * 1e-6
        self.clocks = [resource_clock(r, spin_margin_s=spin_s) for r in self.resources]
        self.tels: list[TelemetryBlock] = []
        self.tel: TelemetryBlock | None = None
        self.listener: socket.socket | None = None
        self.conn: socket.socket | None = None
        self.cmdd: subprocess.Popen[bytes] | None = None
        self.cmdd_pidfd = -1
        self.respawn_at = 0.0
        self.respawn_delay_s = RESPAWN_DELAY_S / 2  # doubled before the first respawn
        self.cmdd_started = 0.0
        self.stop_requested = ""
        self.started = False  # every unit's control thread ticks
        self.memory_locked = False  # by `lock_memory_early` at startup
        self.inbox: deque[Request] = deque()  # requests waiting for the loop's slack
        self.inbox_since_ns = 0
        self.pending: list[tuple[Any, Pending]] = []  # (request id, reply to complete)
        self.urgent: UrgentSocket | None = None
        # to the command daemon when its link has room again, in order (`_send`); discarded:
        # by kind (`reply`, `one_way_error`, a push's name), told to it (`link_discarded`)
        self.outbox: deque[bytes] = deque()
        self.outbox_kinds: deque[str] = deque()
        self.discarded: dict[str, int] = {}
        self.discarded_told = 0  # the total the command daemon was last told of
        self.discard_logged_s = 0.0

    # ---- startup --------------------------------------------------------------------------
    def start(self) -> None:
        daemon = self.cell.daemon
        # the socket's place first: nothing is started for a daemon that could not be reached
        self.gid = prepare_socket_dir(Path(self.socket_path).parent, daemon.socket_group)
        check_socket_path(Path(self.socket_path))
        check_socket_path(Path(urgent_socket_path(self.socket_path)))
        holds = [load_task_file(c.resolve(c.daemon.hold_task)) for c in self.cell.resources]  # checked first
        for i, c in enumerate(self.cell.resources):
            ticks = int(TICK_RING_S / c.control_period_s)
            # the first carries the trace too (the automaton's, of every resource)
            signals = backend_class(c.resource.backend, c.source).describe(c).signals
            layout = Layout(c.dof, ticks, 8192 if i == 0 else 16, sum(g.size for g in signals))
            self.tels.append(TelemetryBlock.create(layout, c.control_period_s))
        self.tel = self.tels[0]
        self._open_socket()
        if not self.args.no_command_daemon:
            # started while the resource configures (it starts up meanwhile, on the other core);
            # it binds the public socket only once this process answers it (`run`): no client
            # reaches a daemon that cannot answer yet. A failed start ends it (`abandon`).
            self._spawn_cmdd()
        refused = lock_memory_early()  # before any bus's I/O threads run (runtime.rt)
        for w in refused:
            log.warning("%s", w)
        self.memory_locked = not refused
        for res, hold in zip(self.resources, holds, strict=True):
            try:
                res.configure()
                res.activate(CommandMode[hold.task.command.upper()])  # its Hold task's mode
            except OrccaddError as e:
                if len(self.resources) == 1:
                    raise
                raise ResourceError(f"resource {res.name}: {e}") from None
        self.wake_r, self.wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self.machine = Machine(
            self.cell,
            self.resources,
            self.clocks,
            self.tels,
            self.wake_w,
            allow_fault_injection=self.args.allow_fault_injection,
        )
        self.urgent = UrgentSocket(urgent_socket_path(self.socket_path), daemon, self.gid, self._urgent)
        # each resource is held (its Hold task) while the startup mission loads
        for u in self.machine.units:
            try:
                u.start_control(self._enter_realtime, daemon.control_priority)
            except OrccaddError as e:
                raise ResourceError(f"resource {u.name}: {e}") from None
        self.started = True
        if self.args.mission:
            reply = self.machine.command("load", {"path": str(Path(self.args.mission).resolve())})
            while isinstance(reply, Pending):  # the automaton thread has not started serving yet
                reply = reply.poll() or (reply.expire() if time.monotonic_ns() > reply.deadline_ns else reply)
                time.sleep(0.01)

    def _open_socket(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.rt_path)
        s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK)
        old = os.umask(0o177)
        try:
            s.bind(self.rt_path)  # 0600: only this user (the command daemon runs as it)
        finally:
            os.umask(old)
        s.listen(2)
        self.listener = s

    def _spawn_cmdd(self) -> None:
        assert self.tel is not None
        cmd = [
            sys.executable, "-m", "orccadd.cmdd", "--config", self.cell.source, "--socket", self.socket_path,
            "--rt-socket", self.rt_path, "--telemetry", self.tel.name,
        ]  # fmt: skip
        # its own process group: a group-wide SIGTERM/SIGINT reaches this process alone, which
        # safe-stops the arm first and then ends its children (systemd: KillMode=mixed)
        self.cmdd = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, start_new_session=True)
        self.cmdd_started = time.monotonic()
        try:
            self.cmdd_pidfd = os.pidfd_open(self.cmdd.pid)
        except OSError:
            self.cmdd_pidfd = -1

    def _enter_realtime(self, priority: int) -> RealtimeReport:
        """SCHED_FIFO `priority` for the calling thread; the memory was locked and collected at
        startup, before the buses' threads ran (`lock_memory_early`): not again."""
        rt = enter_realtime(priority, lock_memory=not self.memory_locked, collect_gc=False)
        rt.memory_locked = rt.memory_locked or self.memory_locked
        return rt

    # ---- the automaton thread (main) ------------------------------------------------------
    def run(self) -> int:
        rt = self._enter_realtime(self.cell.daemon.automaton_priority)
        for w in rt.warnings:
            log.warning("automaton thread: %s", w)
        sig_r, sig_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        signal.set_wakeup_fd(sig_w, warn_on_full_buffer=False)
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._on_signal)
        log.info(
            "%s (%s), socket %s, %s",
            self.cell.name,
            "; ".join(
                f"{c.resource.name}: {c.dof} joints, {c.resource.backend}, "
                f"period {c.control_period_s * 1e3:g} ms"
                for c in self.cell.resources
            ),
            self.socket_path,
            rt.describe(),
        )
        self.notifier.send("READY=1", f"STATUS=idle on {self.socket_path}")
        next_ping = 0.0
        poller = select.poll()
        registered: set[int] = set()
        try:
            while not self.stop_requested:
                fds = {self.wake_r, sig_r, self.listener.fileno() if self.listener else -1}
                if self.conn is not None:
                    fds.add(self.conn.fileno())
                if self.cmdd_pidfd >= 0:
                    fds.add(self.cmdd_pidfd)
                if self.urgent is not None:
                    fds.update(self.urgent.fds())
                if self.inbox:
                    fds.add(self.machine.pacing.loop.slack_fd)
                fds.discard(-1)
                for fd in registered - fds:
                    poller.unregister(fd)
                for fd in fds - registered:
                    poller.register(fd, select.POLLIN)
                registered = fds
                busy = bool(self.inbox or self.pending or self.outbox)
                period_ms = self.machine.pacing.cfg.control_period_s * 1e3
                ready = poller.poll(max(1, int(period_ms)) if busy else 100)
                with self.machine.reactor.held():  # the control thread reacts to nothing meanwhile
                    self._work(ready, sig_r)
                if self.cmdd is None and self.respawn_at and time.monotonic() >= self.respawn_at:
                    self.respawn_at = 0.0
                    self._spawn_cmdd()
                now = time.monotonic()
                if now >= next_ping:
                    next_ping = now + self._ping()
                    if self.urgent is not None:
                        self.urgent.expire()
        finally:
            code = self.shutdown()
            leave_realtime(rt)
        return code

    def _work(self, ready: list[tuple[int, int]], sig_r: int) -> None:
        """What woke the automaton thread: the control thread's events, signals, the command
        daemon's link and commands, the urgent channel; then the commands' replies."""
        for fd, _ in ready:
            if fd == self.wake_r:
                with contextlib.suppress(BlockingIOError):
                    os.read(self.wake_r, 4096)
                self.machine.on_events()
            elif fd == sig_r:
                with contextlib.suppress(BlockingIOError):
                    os.read(sig_r, 64)
            elif self.listener is not None and fd == self.listener.fileno():
                self._accept()
            elif self.conn is not None and fd == self.conn.fileno():
                self._receive()
            elif fd == self.cmdd_pidfd:
                self._cmdd_exited()
            elif self.urgent is not None:
                self.urgent.on_readable(fd)
        self._serve_inbox()
        self._complete_pending()
        self._flush()

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop_requested = signal.Signals(signum).name

    def _healthy(self) -> bool:
        """Each unit's control loop ticking (its heartbeat fresh, in its own periods), or ended
        and recorded as that resource's fault (safe-stopped, waiting for a reset)."""
        now = time.monotonic_ns()
        return self.started and all(
            u.heartbeat_fresh(now) if u.control_running() else u.supervisor.fault is not None
            for u in self.machine.units
        )

    def _ping(self) -> float:
        """WATCHDOG=1 only while the control loop is healthy; returns when to ping next."""
        wd = self.notifier.watchdog_s
        if not wd:
            return 1.0
        if self._healthy():
            self.notifier.send("WATCHDOG=1")
        return max(0.05, wd / 4)

    # ---- the command daemon link ----------------------------------------------------------
    def _accept(self) -> None:
        assert self.listener is not None
        try:
            conn, _ = self.listener.accept()
        except BlockingIOError:
            return
        conn.setblocking(False)
        if self.conn is not None:  # a new command daemon attaches: it replaces the old link
            self.conn.close()
        self.conn = conn
        self.machine.mission.cell_output = self._push_cell_output
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
        rid, reply = self._handle(req)
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

    def _push_cell_output(self, name: str, mission: str) -> None:
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

    def _urgent(self, req: Request) -> dict[str, Any]:
        """An abort or a stop from the urgent socket (never a Pending: both act at once)."""
        rid, reply = self._handle(req)
        return reply if isinstance(reply, dict) else {"id": rid, "ok": False, "error": "not served here"}

    def _handle(self, req: Request) -> tuple[Any, dict[str, Any] | Pending]:
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

    def _cmdd_exited(self) -> None:
        if self.cmdd is not None:
            code = self.cmdd.poll()
            if code is None:
                return
            self.cmdd = None
        if self.cmdd_pidfd >= 0:
            os.close(self.cmdd_pidfd)
            self.cmdd_pidfd = -1
        self.machine.link_lost(f"command daemon exited (code {code})")
        self.machine.publish()
        # one that dies at once (its socket unusable) is retried ever more slowly, not in a loop
        short_lived = time.monotonic() - self.cmdd_started < RESPAWN_STABLE_S
        self.respawn_delay_s = (
            min(RESPAWN_MAX_S, 2 * self.respawn_delay_s) if short_lived else RESPAWN_DELAY_S
        )
        log.warning("command daemon exited (code %s): restarting it in %g s", code, self.respawn_delay_s)
        self.respawn_at = time.monotonic() + self.respawn_delay_s

    # ---- shutdown -------------------------------------------------------------------------
    def abandon(self) -> None:
        """Undo a failed `start` (nothing moved yet): release what was acquired."""
        if hasattr(self, "machine"):
            for u in self.machine.units:
                u.stop()
            self.machine.close_outputs(JOIN_S)  # every unit's threads, its control thread too
        if self.cmdd is not None:
            self.cmdd.terminate()
            self.cmdd.wait()
        if self.listener is not None:
            self.listener.close()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.rt_path)
        for res in self.resources:
            with contextlib.suppress(OrccaddError):
                res.shutdown()
        for tel in self.tels:
            tel.close()

    def shutdown(self) -> int:
        m = self.machine
        why = self.stop_requested
        log.info("stopping (%s): safe stop first", why)
        self.notifier.send("STOPPING=1", f"STATUS=stopping ({why})")
        if m.mission.running:
            m.mission.result = MissionResult.STOPPED
        m.pub.trace(Trace.COMMAND, m.now_s(), OperatorAction.SHUTDOWN)
        for res in self.resources:
            res.safe_stop()
        timeout_s = max(c.safe_stop.timeout_s for c in self.cell.resources) + 1.0
        deadline = time.monotonic() + timeout_s
        stopped = False
        # a unit whose control thread ended was safe-stopped by it (`safe_stop()`, no tick):
        # its device's stop is all there is to wait for, and its reads are not there to show it
        ticking = [u for u in m.units if u.control_running()]
        while time.monotonic() < deadline and all(u.control_running() for u in ticking):
            if all(u.resource.state.status & Status.STOPPED for u in ticking):
                stopped = True
                break
            time.sleep(0.01)
        failed = [u.name for u in m.units if u.failures]
        for u in m.units:
            u.stop()
        m.rt_commands.close()
        m.close_outputs(JOIN_S)  # every unit's threads: control, outputs, a reset's device work
        m.mission.state = MachineState.IDLE
        m.publish()
        for u in m.units:
            u.loop.close()
        if self.cmdd is not None:
            self.cmdd.terminate()
            try:
                self.cmdd.wait(timeout=3.0)
            except subprocess.TimeoutExpired:
                self.cmdd.kill()
                self.cmdd.wait()
        for s in (self.conn, self.listener):
            if s is not None:
                s.close()
        if self.urgent is not None:
            self.urgent.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.rt_path)
        released = self._release()
        for tel in self.tels:
            tel.close()
        what = "hardware released" if released else "hardware not all released"
        if stopped:
            log.log(
                logging.INFO if released else logging.ERROR,
                "%s at rest, %s",
                "arm" if len(self.resources) == 1 else "every resource",
                what,
            )
        else:
            log.error("safe stop not confirmed, %s", what)
        if failed:
            log.error("the control thread of %s failed while it ran", ", ".join(failed))
        return 1 if failed or not stopped or not released else 0

    def _release(self) -> bool:
        """Each resource's `shutdown` in a thread of its own, all waited for `RELEASE_S` in all:
        a device call that never returns (a port or a bus gone) must not keep SIGTERM from
        ending the process. One that fails or hangs is named in the log; True if none did."""
        failed: list[str] = []

        def release(res: PhysicalResource) -> None:
            try:
                res.shutdown()
            except Exception:
                log.exception("%s: releasing its hardware failed", res.name)
                failed.append(res.name)

        group = ThreadGroup("release")
        for res in self.resources:
            group.start(release, res, name=res.name)
        left = group.join(RELEASE_S)  # names those still running
        return not failed and not left


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="orccadd", description="the orccadd real-time controller daemon")
    ap.add_argument("--config", help="robot config: a file, or the name of a shipped one (--list-configs)")
    ap.add_argument("--list-configs", action="store_true", help="list the shipped robot configs and missions")
    ap.add_argument("--version", action="version", version=version_text())
    ap.add_argument("--mission", help="load this mission at startup (it does not start)")
    ap.add_argument("--socket", help="the command socket (default: the config's daemon.socket)")
    ap.add_argument("--no-command-daemon", action="store_true", help="do not spawn the command daemon")
    ap.add_argument("--allow-fault-injection", action="store_true", help="accept `orccadctl inject`")
    ap.add_argument("--in-process-sim", action="store_true", help="simulate the arm inside this process")
    ap.add_argument(
        "--simulate",
        action="store_true",
        help="every resource of the config on the simulated arm (its model, limits, period; no bus "
        "opened): the mission that will run on the robot, run first on a workstation",
    )
    ap.add_argument("--spin-us", type=float, default=0.0, help="wake early and spin (µs)")
    args = ap.parse_args(argv)
    if args.list_configs:
        print(list_configs())
        return 0
    if not args.config:
        ap.error("--config is required (a file, or a shipped config's name: --list-configs)")
    try:
        setup_logging("orccadd")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    # Only real-time threads live here, but a long Python computation (loading a mission) must
    # hand the GIL to the control thread within a fraction of a period, not the default 5 ms.
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    try:
        cell = load_cell_config(robot_config_path(args.config))
        if args.simulate:
            cell = cell.with_resources(tuple(simulated(c) for c in cell.resources))
            log.info("--simulate: every resource on the simulated arm (%s)", ", ".join(cell.names))
        if not args.in_process_sim:
            # a simulated arm lives in its own process, like a real arm outside the controller
            cell = cell.with_resources(
                tuple(
                    with_backend(c, "sim_process") if c.resource.backend == "sim" else c
                    for c in cell.resources
                )
            )
        proc = RealtimeProcess(cell, args.socket or cell.daemon.socket, args)
    except OrccaddError as e:
        log.error("%s", e)
        return 2
    try:
        proc.start()
    except (OrccaddError, CommandError) as e:
        log.error("%s", e)
        proc.abandon()
        return exit_now(2)
    return exit_now(proc.run())


def exit_now(code: int) -> int:
    """`code`, once every thread the daemon owns has ended; a thread that did not (stuck in a
    device call past its owner's join, named in the log then) must not keep the process alive:
    the process ends without waiting for it, its logs flushed."""
    left = threads_left()
    if left:
        log.error("exiting with %d thread(s) still running: %s", len(left), ", ".join(left))
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
