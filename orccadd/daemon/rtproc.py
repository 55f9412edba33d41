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
spawns and respawns: `cmdd_child`) over a SOCK_SEQPACKET socket whose kernel buffer is the
bounded command queue (`cmdlink`); replies are sent without blocking. Telemetry leaves through
shared memory only. SIGTERM/SIGINT: safe stop first, then the hardware is released.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import select
import signal
import sys
import time
from pathlib import Path
from typing import Any

from orccadd.config.shipped import list_configs, robot_config_path
from orccadd.config.station import StationConfig
from orccadd.daemon.cmdd_child import CommandDaemonChild
from orccadd.daemon.cmdlink import CommandLink, rt_socket_path
from orccadd.daemon.machine import Machine
from orccadd.daemon.notify import Notifier
from orccadd.daemon.replies import CommandError, Pending
from orccadd.daemon.unit import ResourceUnit
from orccadd.daemon.unitlink import UnitLink
from orccadd.daemon.unitproc import EXIT_CONTROL_FAILED
from orccadd.daemon.unitproxy import UnitProxy
from orccadd.daemon.unitshm import UnitChannel
from orccadd.daemon.urgent import UrgentSocket
from orccadd.errors import OrccaddError, ResourceError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.physres import backend_class
from orccadd.physres.base import PhysicalResource
from orccadd.robot import create_resource, load_station_config, station_as_run
from orccadd.runtime import enter_realtime, leave_realtime
from orccadd.runtime.rt import RealtimeReport, lock_memory_early
from orccadd.runtime.threads import ThreadGroup, threads_left
from orccadd.task import load_task_file
from orccadd.task.loop import resource_clock
from orccadd.types import CommandMode, Status
from orccadd.wire.schema import Layout, MachineState, MissionResult, OperatorAction, Trace
from orccadd.wire.socketdir import check_socket_path, prepare_socket_dir, urgent_socket_path
from orccadd.wire.telemetry import TelemetryBlock
from orccadd.wire.version import version_text

log = logging.getLogger("orccadd")

TICK_RING_S = 16.0  # seconds of ticks the telemetry ring keeps
TRACE_LEN = 8192  # trace records the daemon's block keeps (the automaton's, of every resource)
GIL_SWITCH_INTERVAL_S = 0.0002
JOIN_S = 2.0  # how long shutdown waits for a thread (one stuck in a device call is named, then left)
RELEASE_S = 8.0  # how long shutdown waits for the resources' release (one that hangs: named, then left)


class RealtimeProcess:
    def __init__(self, station: StationConfig, socket_path: str, args: argparse.Namespace) -> None:
        self.station = station
        self.args = args
        self.socket_path = socket_path
        self.notifier = Notifier()
        self.resources = [create_resource(cfg) for cfg in station.resources]
        spin_s = args.spin_us * 1e-6
        self.clocks = [resource_clock(r, spin_margin_s=spin_s) for r in self.resources]
        self.tels: list[TelemetryBlock] = []  # each resource's: its ticks
        self.block: TelemetryBlock | None = None  # the daemon's own: its status and the trace
        self.link: CommandLink | None = None  # to the command daemon
        self.cmdd: CommandDaemonChild | None = None
        self.stop_requested = ""
        self.started = False  # every unit's control thread ticks
        self.memory_locked = False  # by `lock_memory_early` at startup
        self.urgent: UrgentSocket | None = None
        units = station.daemon.units
        self.in_processes = units == "processes" or (units == "auto" and len(station.resources) > 1)
        self.links: list[UnitLink] = []  # each resource's unit process (units = "processes")
        self.lock_path = ""  # the station's try-lock file: reactions in a tick (units = "processes")

    # ---- startup --------------------------------------------------------------------------
    def start(self) -> None:
        daemon = self.station.daemon
        # the socket's place first: nothing is started for a daemon that could not be reached
        self.gid = prepare_socket_dir(Path(self.socket_path).parent, daemon.socket_group)
        check_socket_path(Path(self.socket_path))
        check_socket_path(Path(urgent_socket_path(self.socket_path)))
        holds = [
            load_task_file(c.resolve(c.daemon.hold_task)) for c in self.station.resources
        ]  # checked first
        for c in self.station.resources:
            ticks = int(TICK_RING_S / c.control_period_s)
            signals = backend_class(c.resource.backend, c.source).describe(c).signals
            layout = Layout(c.dof, ticks, 1, sum(g.size for g in signals))
            self.tels.append(TelemetryBlock.create(layout, c.control_period_s))
        fastest = min(c.control_period_s for c in self.station.resources)
        self.block = TelemetryBlock.create(Layout(0, 1, TRACE_LEN), fastest)
        self.link = CommandLink(rt_socket_path(self.socket_path))
        if not self.args.no_command_daemon:
            # started while the resource configures (it starts up meanwhile, on the other core);
            # it binds the public socket only once this process answers it (`run`): no client
            # reaches a daemon that cannot answer yet. A failed start ends it (`abandon`).
            self.cmdd = CommandDaemonChild(
                self.station.source, self.socket_path, self.link.path, self.block.name
            )
            self.cmdd.spawn()
        refused = lock_memory_early()  # before any bus's I/O threads run (runtime.rt)
        for w in refused:
            log.warning("%s", w)
        self.memory_locked = not refused
        self.wake_r, self.wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        if self.in_processes:
            # each unit process builds, configures and holds its resource (`unitproc`); here,
            # each resource is a shadow the tasks are built on, never configured
            n = len(self.station.resources)
            channels = [UnitChannel.create(units=n, index=k) for k in range(n)]
            self.lock_path = rt_socket_path(self.socket_path) + ".units.lock"
            names = [ch.name for ch in channels]
            for k, (c, tel, ch) in enumerate(zip(self.station.resources, self.tels, channels, strict=True)):
                self.links.append(
                    UnitLink(
                        self.station.source,
                        c.resource.name,
                        tel.name,
                        self.wake_w,
                        simulate=self.args.simulate,
                        in_process_sim=self.args.in_process_sim,
                        spin_us=self.args.spin_us,
                        channel=ch,
                        station=(names, k, self.lock_path),
                    )
                )
                self.links[-1].own_channel = True  # closed with its link
        for res, hold in zip(self.resources, holds, strict=True):
            if self.in_processes:
                break
            try:
                res.configure()
                res.activate(CommandMode[hold.task.command.upper()])  # its Hold task's mode
            except OrccaddError as e:
                if len(self.resources) == 1:
                    raise
                raise ResourceError(f"resource {res.name}: {e}") from None
        self.machine = Machine(
            self.station,
            self.resources,
            self.clocks,
            self.tels,
            self.block,
            self.wake_w,
            allow_fault_injection=self.args.allow_fault_injection,
            links=self.links or None,
        )
        self.link.machine = self.machine
        self.urgent = UrgentSocket(urgent_socket_path(self.socket_path), daemon, self.gid, self.link.urgent)
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

    def _enter_realtime(self, priority: int) -> RealtimeReport:
        """SCHED_FIFO `priority` for the calling thread; the memory was locked and collected at
        startup, before the buses' threads ran (`lock_memory_early`): not again."""
        rt = enter_realtime(priority, lock_memory=not self.memory_locked, collect_gc=False)
        rt.memory_locked = rt.memory_locked or self.memory_locked
        return rt

    # ---- the automaton thread (main) ------------------------------------------------------
    def run(self) -> int:
        rt = self._enter_realtime(self.station.daemon.automaton_priority)
        for w in rt.warnings:
            log.warning("automaton thread: %s", w)
        sig_r, sig_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        signal.set_wakeup_fd(sig_w, warn_on_full_buffer=False)
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._on_signal)
        log.info(
            "%s (%s), socket %s, %s",
            self.station.name,
            "; ".join(
                f"{c.resource.name}: {c.dof} joints, {c.resource.backend}, "
                f"period {c.control_period_s * 1e3:g} ms"
                for c in self.station.resources
            ),
            self.socket_path,
            rt.describe(),
        )
        self.notifier.send("READY=1", f"STATUS=idle on {self.socket_path}")
        next_ping = 0.0
        poller = select.poll()
        registered: set[int] = set()
        link = self.link
        assert link is not None
        try:
            while not self.stop_requested:
                fds = {self.wake_r, sig_r, *link.fds(), *self._unit_fds()}
                if self.cmdd is not None:
                    fds.add(self.cmdd.pidfd)
                if self.urgent is not None:
                    fds.update(self.urgent.fds())
                fds.discard(-1)
                for fd in registered - fds:
                    poller.unregister(fd)
                for fd in fds - registered:
                    poller.register(fd, select.POLLIN)
                registered = fds
                period_ms = self.machine.pacing.cfg.control_period_s * 1e3
                ready = poller.poll(max(1, int(period_ms)) if link.busy else 100)
                with self.machine.reactor.held():  # the control thread reacts to nothing meanwhile
                    self._work(ready, sig_r, link)
                    self.machine.watch(time.monotonic_ns())  # a control thread that hangs
                if self.cmdd is not None:
                    self.cmdd.respawn_due()
                now = time.monotonic()
                if now >= next_ping:
                    next_ping = now + self._ping()
                    if self.urgent is not None:
                        self.urgent.expire()
        finally:
            code = self.shutdown()
            leave_realtime(rt)
        return code

    def _work(self, ready: list[tuple[int, int]], sig_r: int, link: CommandLink) -> None:
        """What woke the automaton thread: the control thread's events, signals, the command
        daemon's link and commands, the urgent channel; then the commands' replies."""
        if self.machine.refresh():  # each unit's state; a unit's failure (its process's end)
            self.machine.on_events()
        for fd, _ in ready:
            if fd == self.wake_r:
                with contextlib.suppress(BlockingIOError):
                    os.read(self.wake_r, 4096)
                self.machine.on_events()
            elif fd == sig_r:
                with contextlib.suppress(BlockingIOError):
                    os.read(sig_r, 64)
            elif link.on_readable(fd):
                pass
            elif self.cmdd is not None and fd == self.cmdd.pidfd:
                code = self.cmdd.exited()
                if code is not None:
                    self.machine.link_lost(f"command daemon exited (code {code})")
                    self.machine.publish()
            elif self.urgent is not None:
                self.urgent.on_readable(fd)
        link.after_work()

    def _unit_fds(self) -> set[int]:
        """The link and the pidfd of each unit process still running."""
        links = [u.link for u in self.machine.units if isinstance(u, UnitProxy)]
        return {
            fd for k in links if k.proc.poll() is None and not k.closed for fd in (k.sock.fileno(), k.pidfd)
        }

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.stop_requested = signal.Signals(signum).name

    def _healthy(self) -> bool:
        """Each unit's control loop ticking (its heartbeat fresh, in its own periods), or ended and
        recorded as that resource's fault (safe-stopped; `reset` starts it again). One that hangs
        in a device call is not fine even once faulted: nothing in the daemon can end that call,
        so the pings stop and the service manager restarts the daemon if it never returns."""
        now = time.monotonic_ns()

        def fine(u: ResourceUnit | UnitProxy) -> bool:
            ended = not u.control_running() and u.supervisor.fault is not None
            return u.heartbeat_fresh(now) or ended

        return self.started and all(fine(u) for u in self.machine.units)

    def _ping(self) -> float:
        """WATCHDOG=1 only while the control loop is healthy; returns when to ping next."""
        wd = self.notifier.watchdog_s
        if not wd:
            return 1.0
        if self._healthy():
            self.notifier.send("WATCHDOG=1")
        return max(0.05, wd / 4)

    # ---- shutdown -------------------------------------------------------------------------
    def abandon(self) -> None:
        """Undo a failed `start` (nothing moved yet): release what was acquired."""
        if hasattr(self, "machine"):
            for u in self.machine.units:
                u.stop()
            self.machine.join_units(JOIN_S)  # every unit's threads, its control thread too
        if self.cmdd is not None:
            self.cmdd.end(wait_s=None)
        if self.link is not None:
            self.link.close()
        started = hasattr(self, "machine")  # the machine's units hold the links now (a reset renews them)
        for link in (
            [u.link for u in self.machine.units if isinstance(u, UnitProxy)] if started else self.links
        ):
            link.end()  # its resource released by the unit itself
        for res in [] if self.in_processes else self.resources:
            with contextlib.suppress(OrccaddError):
                res.shutdown()
        for tel in [*self.tels, *([self.block] if self.block else [])]:
            tel.close()

    def shutdown(self) -> int:
        m = self.machine
        why = self.stop_requested
        log.info("stopping (%s): safe stop first", why)
        self.notifier.send("STOPPING=1", f"STATUS=stopping ({why})")
        if m.mission.running:
            m.mission.result = MissionResult.STOPPED
        m.pub.trace(Trace.COMMAND, m.now_s(), OperatorAction.SHUTDOWN)
        for u in m.units:
            u.resource.safe_stop()
        timeout_s = max(c.safe_stop.timeout_s for c in self.station.resources) + 1.0
        deadline = time.monotonic() + timeout_s
        stopped = False
        # a unit whose control thread ended was safe-stopped by it (`safe_stop()`, no tick):
        # its device's stop is all there is to wait for, and its reads are not there to show it
        ticking = [u for u in m.units if u.control_running()]
        while time.monotonic() < deadline and all(u.control_running() for u in ticking):
            m.refresh()
            if all(u.resource.state.status & Status.STOPPED for u in ticking):
                stopped = True
                break
            time.sleep(0.01)
        failed = [u.name for u in m.units if u.failures]
        for u in m.units:
            u.stop()
        m.rt_commands.close()
        # every unit's threads: control, outputs, a reset's device work; a unit process's end
        # releases its hardware too: it has as long as a release has
        m.join_units(RELEASE_S if self.in_processes else JOIN_S)
        m.mission.state = MachineState.IDLE
        m.publish()
        for u in m.units:
            u.loop.close()
        if self.cmdd is not None:
            self.cmdd.end()
        if self.link is not None:
            self.link.close()
        if self.urgent is not None:
            self.urgent.close()
        released = self._release()
        if self.lock_path:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.lock_path)
        for tel in [*self.tels, *([self.block] if self.block else [])]:
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

        if self.in_processes:  # each unit process released its own at its end
            for u in self.machine.units:
                code = u.link.proc.returncode if isinstance(u, UnitProxy) else None
                if code not in (0, EXIT_CONTROL_FAILED):  # that one: logged after
                    log.error("%s: its unit process ended with %s", u.name, code)
                    failed.append(u.name)
            return not failed
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
        station = load_station_config(robot_config_path(args.config))
        if args.simulate:
            log.info("--simulate: every resource on the simulated arm (%s)", ", ".join(station.names))
        station = station_as_run(station, args.simulate, args.in_process_sim)
        proc = RealtimeProcess(station, args.socket or station.daemon.socket, args)
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
