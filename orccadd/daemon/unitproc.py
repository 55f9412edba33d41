"""A resource's unit in a process of its own: one clock domain, one interpreter (issue 44, item
2; work in progress on branch unit-process, not wired into the daemon yet).

`python -m orccadd.daemon.unitproc --station FILE --resource NAME --channel SHM --telemetry SHM
--link-fd N --wake-fd N` is started by the automaton's process (`unitlink.UnitLink`). It builds
the resource, configures it, holds it with its Hold task (`ResourceUnit`, as in one process) and
runs its control thread at the station's control priority. Then:

- each tick takes the switch request the automaton's process posted in the channel (a task by
  its index: the Hold tasks of the station's resources in order, then the mission's tasks) and
  pushes its events into the channel's ring, waking the automaton's process through the
  inherited `--wake-fd`;
- the link's requests are served on a thread of their own: `load` builds the mission's tasks,
  `safe_stop`, `inject`, `end`;
- every event id is the automaton process's own by construction: this process builds every task
  both build — the Hold task of each resource of the station, then each mission's tasks — in the
  same order, those of the other resources on their resource built and never configured (no bus
  opened). A `load` compares the two registries' names and is refused on any difference;
- the end of the link (the automaton's process gone) is a safe stop: the unit stops its
  resource, releases it and exits.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.config.station import StationConfig
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.mission import prepare_mission
from orccadd.daemon.reactions import ChannelReactor
from orccadd.daemon.unit import ResourceUnit, hold_name, hold_task
from orccadd.daemon.unitlink import recv_frame, send_frame
from orccadd.daemon.unitshm import ChannelQueue, TryLock, UnitChannel
from orccadd.errors import OrccaddError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.physres.base import PhysicalResource
from orccadd.robot import create_resource, load_station_config, station_as_run
from orccadd.runtime.clock import Clock
from orccadd.runtime.rt import RealtimeReport, enter_realtime, lock_memory_early
from orccadd.task import EventQueue, EventRegistry, RobotTask, load_task_file
from orccadd.task.events import EventKind
from orccadd.task.loop import resource_clock
from orccadd.types import CommandMode, Status
from orccadd.wire.schema import H
from orccadd.wire.telemetry import TelemetryBlock

log = logging.getLogger("orccadd.unit")
REST_WAIT_S = 5.0  # how long the end waits for the resource at rest before releasing it
# the unit's exit codes past 0 (released, at rest): what went wrong, for the real-time process
EXIT_CONTROL_FAILED = 1  # its control thread failed while it ran (released, at rest)
EXIT_NOT_RELEASED = 3  # releasing the resource failed
EXIT_NOT_AT_REST = 4  # not at rest within REST_WAIT_S


class ChannelLoop(SwitchingLoop):
    """The control loop of a unit process: at each tick's start, the switch request the
    automaton's process posted in the channel (a task index into `tasks`) becomes this loop's."""

    channel: UnitChannel
    tasks: list[RobotTask]  # by index: the station's Hold tasks in order, then the mission's

    def step(self, t_s: float) -> None:
        if self.channel.take_stop():
            self.request_safe_stop()
        taken = self.channel.take_switch()
        if taken is not None:
            index, fresh = taken
            tasks = self.tasks
            if 0 <= index < len(tasks) and tasks[index].resource is self.resource:
                self.request_switch(tasks[index], fresh)
            else:  # not this resource's: the automaton's process asked for what it cannot be
                self.request_switch(self.hold, fresh=False)
        super().step(t_s)


class UnitProcess:
    """One resource's unit, the tasks built for it, and the link's server."""

    def __init__(
        self,
        station: StationConfig,
        resource: str,
        channel: UnitChannel,
        tel: TelemetryBlock,
        link: socket.socket,
        wake_fd: int,
        spin_us: float = 0.0,
    ) -> None:
        if resource not in station.names:
            raise OrccaddError(
                f"{station.source}: no resource {resource!r} (resources: {', '.join(station.names)})"
            )
        self.station = station
        self.channel = channel
        self.link = link
        self.registry = EventRegistry()
        self.queue = ChannelQueue(channel)
        self.send_lock = threading.Lock()
        self.resource: PhysicalResource
        self.unit: ResourceUnit
        # every resource of the station, this one's real, the others built and never configured;
        # each one's Hold task, in the station's order (the automaton process's event ids)
        self.bindings: dict[str, tuple[PhysicalResource, EventQueue]] = {}
        self.holds: list[RobotTask] = []
        for cfg in station.resources:
            name = cfg.resource.name
            if name == resource:
                self.resource = create_resource(cfg)
                self.cfg = cfg
                clock = resource_clock(self.resource, spin_margin_s=spin_us * 1e-6)
                self.unit = self._unit(cfg, clock, tel, wake_fd, hold_name(station.listed, name))
                self.bindings[name] = (self.resource, self.queue)
                self.holds.append(self.unit.loop.hold)
            else:
                other = create_resource(cfg)
                queue = EventQueue(1)  # never ticked here: its events go nowhere
                self.bindings[name] = (other, queue)
                self.holds.append(
                    hold_task(cfg, other, self.registry, queue, hold_name(station.listed, name))
                )
        self.loop.tasks = list(self.holds)
        # a unit started again (its process had died) counts on in its telemetry block
        self.loop.stats.continue_from(int(tel.header[H.TICKS]), int(tel.header[H.OVERRUNS]))
        self.loop.switches = int(tel.header[H.SWITCHES])
        self.loop.set_task_ids({id(t): i for i, t in enumerate(self.holds)})
        self.unit.on_failure = lambda why: self.tell({"op": "failed", "why": why})
        self.queue.before_push = self._before_push
        self.kinds = self.registry.kinds()
        self.ended = threading.Event()
        self.reactor: ChannelReactor | None = None

    def _unit(
        self, cfg: RobotConfig, clock: Clock, tel: TelemetryBlock, wake_fd: int, name: str
    ) -> ResourceUnit:
        unit = ResourceUnit(
            cfg,
            self.resource,
            clock,
            tel,
            self.registry,
            wake_fd,
            hold_name=name,
            queue=self.queue,
            loop_type=ChannelLoop,
        )
        loop = unit.loop
        assert isinstance(loop, ChannelLoop)
        loop.channel = self.channel
        return unit

    @property
    def loop(self) -> ChannelLoop:
        loop = self.unit.loop
        assert isinstance(loop, ChannelLoop)
        return loop

    def react_in_ticks(self, reactor: ChannelReactor) -> None:
        """Take the automaton's published reactions in the tick of their event."""
        self.reactor = reactor
        reactor.tasks = self.loop.tasks
        self.loop.reactor = reactor

    # ---- startup and the end ----------------------------------------------------------------
    def start(self) -> None:
        """Configure the resource, hold it; `holding` told once the loop has ticked."""
        hold = load_task_file(self.cfg.resolve(self.cfg.daemon.hold_task))
        for w in lock_memory_early():
            log.warning("%s", w)
        self.resource.configure()
        self.resource.activate(CommandMode[hold.task.command.upper()])
        self.unit.start_control(self._enter_realtime, self.station.daemon.control_priority)
        self.tell(
            {
                "op": "holding",
                "pid": os.getpid(),
                "helper_pid": self.resource.helper_pid(),
                "tasks": [t.name for t in self.loop.tasks],
                "events": self.registry.names(),
            }
        )

    def _enter_realtime(self, priority: int) -> RealtimeReport:
        return enter_realtime(priority, lock_memory=False, collect_gc=False)

    def end(self) -> int:
        """Safe stop, the resource at rest (or `REST_WAIT_S`), the loop stopped, the resource
        released. 0 if it came to rest and was released."""
        res = self.resource
        res.safe_stop()
        end = time.monotonic() + REST_WAIT_S
        at_rest = False
        while time.monotonic() < end and self.unit.control_running():
            if res.state.status & Status.STOPPED:
                at_rest = True
                break
            time.sleep(0.01)
        at_rest = at_rest or not self.unit.control_running()
        self.unit.stop()
        left = self.unit.join(2.0)
        if left:
            log.error("%s: thread(s) still running at the end: %s", res.name, ", ".join(left))
        self.loop.close()
        try:
            res.shutdown()
        except OrccaddError as e:
            log.error("%s: releasing it failed: %s", res.name, e)
            return EXIT_NOT_RELEASED
        if not at_rest:
            log.error("%s: not at rest within %g s of its safe stop", res.name, REST_WAIT_S)
            return EXIT_NOT_AT_REST
        return EXIT_CONTROL_FAILED if self.unit.failures else 0

    # ---- the link ---------------------------------------------------------------------------
    def tell(self, msg: dict[str, Any]) -> None:
        """A message to the automaton's process (from any thread of this one)."""
        with self.send_lock, contextlib.suppress(OSError):
            send_frame(self.link, msg)

    def serve(self) -> None:
        """The link's requests, until `end` or the link's end."""
        while True:
            try:
                msg = recv_frame(self.link)
            except (OSError, OrccaddError) as e:
                log.error("%s: the link to the automaton's process broke: %s", self.resource.name, e)
                msg = None
            if msg is None:
                log.warning("%s: the automaton's process is gone: safe stop", self.resource.name)
                return
            op, rid = msg.get("op"), msg.get("id")
            if op == "end":
                return
            try:
                answer = self.handle(str(op), msg)
            except (OrccaddError, ValueError, KeyError, TypeError) as e:
                self.tell({"id": rid, "error": str(e)})
            else:
                if answer is not None:
                    self.tell({"id": rid, "ok": True, **answer})

    def _before_push(self, event_id: int) -> None:
        """A type 3's fault goes to the automaton's process before its event (the control
        thread's, the rare path): `Machine.on_events` reads it as it drains the event."""
        kinds = self.kinds
        if event_id < len(kinds) and kinds[event_id] is EventKind.T3:
            info = self.registry.info(event_id)
            task = next((t for t in self.loop.tasks if t.name == info.task), None)
            if task is not None and task.fault is not None:
                self.tell({"op": "t3", "task": task.name, "fault": task.fault})

    def handle(self, op: str, msg: dict[str, Any]) -> dict[str, Any] | None:
        """A request's answer (None: answered later, by a thread of the unit)."""
        if op == "load":
            return self._load(msg)
        if op == "tune":
            return self._tune(int(msg["task"]), str(msg["path"]), msg["value"])
        if op == "output":
            self.unit.outputs.request(str(msg["name"]))
            return {}
        if op == "reset":
            self._reset(msg["id"], float(msg["wait_s"]))
            return None
        if op == "stalled":  # found so by the automaton's process (no tick for its watchdog)
            self.unit.threads.start(self.unit.stop_stalled, name="stall-safe-stop")
            return {"line": self.unit.control_line()}
        if op == "diagnostics":
            return {"diagnostics": self.resource.diagnostics(), "fault": self.resource.fault_message}
        if op == "inject":
            return self._inject(msg)
        raise ValueError(f"no request {op!r} for a unit")

    def _tune(self, task: int, path: str, value: Any) -> dict[str, Any]:
        """The change checked again here, posted to the loop; answered with the tick that
        applied it (within 100 periods, at least 2 s)."""
        tasks = self.loop.tasks
        if not 0 <= task < len(tasks) or tasks[task].resource is not self.resource:
            raise ValueError(f"task {task}: not a task of {self.resource.name}")
        seq = self.loop.tunes.post(tasks[task].prepare_tune(path, value))
        end = time.monotonic() + max(100 * self.cfg.control_period_s, 2.0)
        while (tick := self.loop.tunes.acked(seq)) is None:
            if time.monotonic() > end or not self.unit.control_running():
                raise OrccaddError("the control loop has not applied it (not running?)")
            time.sleep(0.0005)
        return {"tick": tick}

    def _reset(self, rid: int, wait_s: float) -> None:
        """The device's reset on a thread of the unit; answered when it ends."""
        device = self.unit.device_reset(wait_s)

        def watch() -> None:
            try:
                while not device.done():
                    time.sleep(0.005)
            except OrccaddError as e:
                self.tell({"id": rid, "error": str(e)})
            else:
                self.unit.stalled = ""
                self.tell({"id": rid, "ok": True})

        self.unit.threads.start(watch, name="reset-answer")

    def _load(self, msg: dict[str, Any]) -> dict[str, Any]:
        """The mission's tasks built on every resource (this one's for real), in the automaton
        process's order, the registry seeded with the automaton's; its names must then be this
        one's."""
        self.registry.seed(msg.get("registry", []))
        loaded = prepare_mission(
            msg["path"],
            msg["automaton"],
            msg["report"],
            self.bindings,
            self.registry,
            msg["specs"],
            msg.get("data"),
        )
        names = self.registry.names()
        if names != msg["events"]:
            differ = next(
                (i for i, (a, b) in enumerate(zip(names, msg["events"], strict=False)) if a != b), None
            )
            where = (
                f"from id {differ}" if differ is not None else f"{len(names)} against {len(msg['events'])}"
            )
            raise OrccaddError(f"the unit's event ids are not the automaton's ({where}): mission refused")
        tasks = [*self.holds, *loaded.tasks]
        self.loop.set_task_ids({id(t): i for i, t in enumerate(tasks)})
        self.loop.set_input_events(tuple(int(e) for e in msg.get("input_events", ())))
        self.loop.tasks = tasks  # one store: a tick sees the old list or the new
        if self.reactor is not None:
            self.reactor.tasks = tasks
        self.kinds = self.registry.kinds()
        return {"tasks": [t.name for t in tasks]}

    def _inject(self, msg: dict[str, Any]) -> dict[str, Any]:
        kind = str(msg["kind"])
        if kind == "control_thread":
            self.loop.inject_failure()
        elif kind == "hang":
            self.loop.inject_hang(float(msg["seconds"]))
        elif kind == "overrun":
            self.loop.inject_overrun(int(msg["ticks"]), int(msg["extra_ns"]))
        elif kind == "resource":
            self.resource.inject_fault(str(msg["fault"]), str(msg["message"]))
        elif kind == "crash":
            os._exit(70)  # the unit process dies at once, as a segfault in a driver would
        else:
            raise ValueError(f"no fault {kind!r} to inject in a unit")
        return {}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="orccadd-unit", description="one resource of orccadd, in its own process"
    )
    ap.add_argument("--station", required=True)
    ap.add_argument("--resource", required=True)
    ap.add_argument("--channel", required=True, help="the unit's shared channel (its name)")
    ap.add_argument("--telemetry", required=True, help="the resource's telemetry block (its name)")
    ap.add_argument("--link-fd", type=int, required=True)
    ap.add_argument("--wake-fd", type=int, required=True)
    ap.add_argument("--spin-us", type=float, default=0.0)
    ap.add_argument("--channels", default="", help="every unit's channel, in the station's order")
    ap.add_argument("--index", type=int, default=0, help="this unit's among them")
    ap.add_argument("--lock", default="", help="the station's try-lock file (reactions in a tick)")
    ap.add_argument("--simulate", action="store_true")
    ap.add_argument("--in-process-sim", action="store_true")
    args = ap.parse_args(argv)
    try:
        setup_logging("orccadd.unit")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    link = socket.socket(fileno=args.link_fd)
    os.set_inheritable(args.wake_fd, False)
    channel = UnitChannel.attach(args.channel)
    tel = TelemetryBlock.attach(args.telemetry)
    try:
        station = station_as_run(load_station_config(Path(args.station)), args.simulate, args.in_process_sim)
        unit = UnitProcess(station, args.resource, channel, tel, link, args.wake_fd, args.spin_us)
        if args.lock:
            others = [
                channel if i == args.index else UnitChannel.attach(n)
                for i, n in enumerate(args.channels.split(","))
            ]
            unit.react_in_ticks(ChannelReactor(others, args.index, TryLock(args.lock)))
        unit.start()
    except OrccaddError as e:
        log.error("%s", e)
        with contextlib.suppress(OSError):
            send_frame(link, {"op": "refused", "error": str(e)})
        return 2
    # the service manager's SIGTERM reaches every process of the service: here it ends the link
    # (the blocked read returns), and the unit ends as when the automaton's process is gone
    signal.signal(signal.SIGTERM, lambda signum, frame: link.shutdown(socket.SHUT_RD))
    unit.serve()
    code = unit.end()
    tel.close()
    channel.close()
    return code


if __name__ == "__main__":
    sys.exit(main())
