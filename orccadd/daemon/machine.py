"""The execution machine (seed §5.1–5.3): the automaton thread's side of the real-time process.

It puts the parts together and routes between them, each found by name:

- `SwitchingLoop` (loop.py): the control thread's side: switch and tune mailboxes, telemetry;
- `MissionControl` (procedure.py): the mission's lifecycle and the automaton's reactions;
- `InlineReactor` (inline.py): the same reactions taken by the control thread in the tick of
  their event, when the automaton thread is idle and up to date;
- `Supervisor` (supervision.py): type 3 faults, aborts, resets, the command daemon's link;
- `RtCommands` (commands.py): the operator's commands, bound to the wire's command table;
- `Publisher` (publisher.py): trace records and the status area of the telemetry block.

Everything here runs in the highest-priority thread and never blocks: commands arrive parsed,
long ones return a `Pending` reply completed by later ticks.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.config.station import StationConfig
from orccadd.daemon.commands import RtCommands, describe_resource
from orccadd.daemon.inline import InlineReactor
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.publisher import Publisher
from orccadd.daemon.reactions import ReactionTables
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.daemon.supervision import FaultHistory, Supervisor
from orccadd.daemon.unit import ResourceUnit, hold_name
from orccadd.daemon.unitlink import UnitLink
from orccadd.daemon.unitproxy import UnitProxy
from orccadd.daemon.unitshm import TryLock
from orccadd.fault import Fault, FaultKind, StopCause
from orccadd.physres.base import PhysicalResource
from orccadd.runtime.clock import Clock
from orccadd.task import EventRegistry, RobotTask
from orccadd.task.events import EventKind
from orccadd.wire.commands import COMMANDS, Dispatcher, with_defaults
from orccadd.wire.schema import MissionResult, S, Trace, status_names
from orccadd.wire.telemetry import TelemetryBlock

log = logging.getLogger("orccadd.machine")
NOTES_KEPT = 50


class Machine:
    """Missions, the automaton and commands, over every resource of the daemon (`units`, in the
    config's order, each a `ResourceUnit`: no resource is special). Methods run in the automaton
    thread only."""

    def __init__(
        self,
        station: StationConfig,
        resources: Sequence[PhysicalResource],
        clocks: Sequence[Clock],
        telemetry: Sequence[TelemetryBlock],
        block: TelemetryBlock,
        wake_fd: int,
        *,
        allow_fault_injection: bool = False,
        links: Sequence[UnitLink | None] | None = None,
    ) -> None:
        """`telemetry`: each resource's block (its ticks); `block`: the daemon's own (the status
        area and the trace, of every resource). `links`: per resource, its unit process (its
        resource in `resources` is then the shadow the tasks are built on: never configured),
        or None: its unit runs here, on threads of this process."""
        self.station = station
        self.pub = Publisher(block)
        self.registry = EventRegistry()
        self.faults = FaultHistory()
        self.faults.on_cause = lambda n: self.pub.trace(Trace.FAULT, self.now_s(), code=n)
        links = list(links) if links is not None else [None] * len(resources)
        self.units: tuple[ResourceUnit | UnitProxy, ...] = tuple(
            ResourceUnit(
                cfg, res, clock, tel, self.registry, wake_fd, hold_name=hold_name(station.listed, res.name)
            )
            if link is None
            else UnitProxy(cfg, res, tel, self.registry, link, hold_name=hold_name(station.listed, res.name))
            for cfg, res, clock, tel, link in zip(
                station.resources, resources, clocks, telemetry, links, strict=True
            )
        )
        self.allow_fault_injection = allow_fault_injection
        self.notes: list[str] = []  # recent notable happenings (bounded), for `describe`
        self.mission = MissionControl([u.loop for u in self.units], self.pub, self.note, self.abort)
        self.mission.outputs = {u.name: u.outputs for u in self.units}
        proxies = [u for u in self.units if isinstance(u, UnitProxy)]
        self.reactor: InlineReactor | ReactionTables
        if proxies and proxies[0].link.station is not None:
            lock = TryLock(proxies[0].link.station[2])
            self.reactor = ReactionTables(
                self.mission, self.registry, [u.channel for u in proxies], lock, self._task_id
            )
        else:
            self.reactor = InlineReactor(self.mission, self.registry)
        for u in self.units:
            u.bind(Supervisor(u.cfg, u.resource, u.loop, self.mission, self.note, self.faults))
            u.loop.reactor = self.reactor
        self.mission.publish_task_ids()
        # the daemon's clock (trace times, command times): the fastest resource's, which also
        # paces the automaton thread's work between ticks (`pacing`)
        self.pacing = min(self.units, key=lambda u: u.cfg.control_period_s)
        self.rt_commands = RtCommands(self)
        self.commands = Dispatcher(self.rt_commands, "rt")
        self.publish()

    def join_units(self, timeout_s: float) -> list[str]:
        """Every unit's threads ended (its control thread once stopped: `ResourceUnit.stop`; its
        output actions done; a reset's device work), waited for `timeout_s` in all; the names of
        those still running (a device call that hangs)."""
        end = time.monotonic() + timeout_s
        return [name for u in self.units for name in u.join(max(0.0, end - time.monotonic()))]

    def _task_id(self, task: RobotTask) -> int:
        """`task`'s index among the Hold tasks and the mission's (the units number them so)."""
        return next((i for i, t in enumerate(self.mission.tasks()) if t is task), -1)

    def refresh(self) -> bool:
        """Each unit's state as its control loop last published it (a unit process's, from its
        telemetry block and its link); at each wake-up of the automaton thread. True if a unit
        has a failure to take (`on_events`)."""
        for u in self.units:
            u.refresh()
        return any(u.failure_pending() for u in self.units)

    def unit(self, name: str) -> ResourceUnit | UnitProxy:
        """The resource `name`'s unit; `CommandError` naming those there are."""
        for u in self.units:
            if u.name == name:
                return u
        raise CommandError(f"no resource {name!r} (resources: {', '.join(u.name for u in self.units)})")

    def unit_of(self, task: RobotTask) -> ResourceUnit | UnitProxy:
        return self.unit(task.resource.name)

    @property
    def default(self) -> ResourceUnit | UnitProxy:
        """The resource a client addresses when it names none: the first listed. The wire's
        top-level `joints`, `telemetry`, `resource`, `helper_pid` are its, so that a client of a
        one-resource daemon needs no name; nothing in the daemon itself treats it apart."""
        return self.units[0]

    @property
    def fault(self) -> StopCause | None:
        """The stop cause of the first resource in the config's order that is safe-stopped
        (None if none is)."""
        return next((u.supervisor.fault for u in self.units if u.supervisor.fault), None)

    def abort(self, why: str, kind: FaultKind = FaultKind.ABORT) -> None:
        """Safe-stop every resource at its next tick, remembering why; end the run (`aborted`)."""
        for u in self.units:
            u.supervisor.stop(why, kind)
        self.note(f"abort: {why}", logging.WARNING)
        self.mission.end(MissionResult.ABORTED)

    def link_lost(self, why: str) -> None:
        """The command daemon's link is gone: noted; the run aborted if the config says so."""
        self.note(why, logging.WARNING)
        if self.station.daemon.on_command_daemon_loss == "safe_stop" and self.mission.running:
            self.abort(f"{why} (on_command_daemon_loss = safe_stop)")

    # ---- helpers ------------------------------------------------------------------------
    def now_s(self) -> float:
        return self.pacing.clock.now_ns() * 1e-9

    def note(self, msg: str, level: int = logging.INFO) -> None:
        """A line for the journal (WARNING for what an operator must see: a safe stop, an abort,
        the safe procedure, a mission that did not succeed) and for `status`."""
        log.log(level, "%s", msg)
        self.notes = [*self.notes[-(NOTES_KEPT - 1) :], f"{time.strftime('%H:%M:%S')} {msg}"]

    def publish(self) -> None:
        mc = self.mission
        self.pub.status(
            {
                S.MACHINE: float(mc.state),
                S.AUTOMATON_STATE: float(mc.runner.number(mc.runner.snapshot()) if mc.runner else -1),
                S.MISSION_GEN: float(mc.generation),
                S.INSTANTS: float(mc.instants),
                S.RESULT: float(mc.result),
                S.FAULTED: float(self.faults.count) if self.fault else 0.0,
                S.HELPER_PID: float(self.default.resource.helper_pid()),
            }
        )

    def describe(self) -> dict[str, Any]:
        mc = self.mission
        d = self.default
        return {
            "robot": self.station.name,
            "config": self.station.source,
            "dof": d.cfg.dof,
            "joints": list(d.cfg.joint_names),
            # the limits the controller enforces, per joint (SI units in the keys)
            "joint_limits": joint_limits(d.cfg),
            "period_s": d.cfg.control_period_s,
            "telemetry": d.tel.name,
            "daemon_telemetry": self.pub.tel.name,  # the daemon's own block: its status and trace
            "resource": describe_resource(d.resource),
            "resources": [self._describe_unit(u) for u in self.units],
            "generation": mc.generation,
            "tasks": [t.name for t in mc.tasks()],
            "hold_tunables": mc.hold.tunable_names,  # the Hold task's (task id 0 of a tune record)
            "events": self.registry.names(),
            "event_kinds": [k.name.lower() for k in self.registry.kinds()],  # post, t1, t2, t3, sync, pre
            "mission": mc.mission.describe() if mc.mission else None,
            "missions": mc.loaded,  # the last ones loaded: the trace names its records by them
            "log": self.notes[-10:],
            "fault": self.fault.to_wire() if self.fault else None,
            "faults": self.faults.recent(),
        }

    def _describe_unit(self, u: ResourceUnit | UnitProxy) -> dict[str, Any]:
        """One resource as an operator sees it: backend, clock, joints, state, fault, telemetry."""
        st = u.resource.state
        return {
            "name": u.name,
            "backend": u.cfg.resource.backend,
            "config": u.cfg.source,
            "clock": u.resource.description.clock.value,  # paced by the device or by our loop
            "period_s": u.cfg.control_period_s,
            "joints": list(u.cfg.joint_names),
            "joint_limits": joint_limits(u.cfg),
            "status": status_names(int(st.status)),
            "task": u.loop.active.name if u.loop.active is not None else None,
            "hold_task": u.loop.hold.name,
            "fault": u.supervisor.fault.to_wire() if u.supervisor.fault else None,
            "telemetry": u.tel.name,
            "helper_pid": u.resource.helper_pid(),  # a simulated arm's plant process (0: none)
            "unit_pid": u.pid,  # the process its control loop runs in (this one's, or its own)
            "hold_tunables": u.loop.hold.tunable_names,
            "description": describe_resource(u.resource),
        }

    # ---- events from the control threads --------------------------------------------------
    def on_events(self) -> None:
        """The control threads' events, every resource's pending ones, in the robot config's
        order of resources and each resource's order of ticks: type 3 to that resource's
        supervisor; the rest to the automaton as the inputs of one instant, but for those a
        control thread reacted to in their tick (`InlineReactor`: booked here)."""
        self.reactor.book()
        mc = self.mission
        mission = mc.mission
        inputs = 0
        t_last = 0.0
        held_fault = ""  # a type 3 of a resource the mission has no input for (it does not declare it)
        faults: list[int] = []  # the mission's `R.fault` inputs: one per instant, in resource order
        for k, u in enumerate(self.units):
            if why := u.take_failure():
                self._control_failed(u, why)
            index, upto = u.queue.tail, self.reactor.upto[k]
            for t_s, eid in u.queue.drain():
                info = self.registry.info(eid)
                if info.kind is EventKind.T3:
                    new = u.supervisor.fault is None  # not a stopped resource's Hold, again
                    u.supervisor.on_t3(info.name, self._task_fault(info.task))
                    if new and mc.running and not self._runs_task(info.task):
                        bit = self._fault_bit(u.name)
                        if bit:
                            faults.append(bit)
                            t_last = max(t_last, t_s)
                        elif len(self.units) > 1:
                            held_fault = f"{u.name} safe-stopped while the run held it ({info.name})"
                bit = mission.event_bits.get(eid, 0) if mission is not None and mc.running else 0
                reacted = index < upto
                index += 1
                if bit:
                    if not reacted:
                        inputs |= bit
                        t_last = max(t_last, t_s)
                else:
                    self.pub.trace(Trace.EVENT, t_s, code=eid)
        if faults:
            inputs |= faults[0]
        if inputs:
            mc.react(t_last, inputs)
        for bit in faults[1:]:  # another resource's fault: the next instant's
            if mc.running:
                mc.react(t_last, bit)
        if held_fault and mc.running:
            self._end_on_held_fault(held_fault)
        self.publish()

    def watch(self, now_ns: int) -> None:
        """Each wake-up of the automaton thread: a unit whose control thread has stopped ticking
        without ending (`ResourceUnit.check_stall`: a device call that hangs) is that resource's
        fault, `comm_lost`; the mission gets its active task's `CommLost` (or `R.fault`), here,
        since that thread, the queue's producer, may yet come back."""
        for u in self.units:
            why = u.check_stall(now_ns)
            if not why:
                continue
            self.note(f"{u.name}: {why}: safe-stopped, the others go on", logging.ERROR)
            task = u.loop.active
            event = f"{task.name}.T3.CommLost" if task is not None else ""
            if u.supervisor.fault is None:
                u.supervisor.on_t3(event, Fault(FaultKind.COMM_LOST, u.name, why))
            mc = self.mission
            if not mc.running or mc.mission is None:
                continue
            # the task's own type 3 if the mission runs it there, else the resource's fault input
            eid = task.builtin_ids.get("CommLost", -1) if task is not None else -1
            bit = mc.mission.event_bits.get(eid, 0) or self._fault_bit(u.name)
            if bit:
                mc.react(self.now_s(), bit)
            else:
                self._end_on_held_fault(f"{u.name} stalled ({why})")
            self.publish()

    def _control_failed(self, u: ResourceUnit | UnitProxy, why: str) -> None:
        """`u`'s control thread ended on `why` (it safe-stopped the resource first): its active
        task's type 3 `LawError` (the controller failed), queued here as its tick would have
        (the thread is gone: this one is the queue's only producer now), so the mission takes
        it as it takes any type 3: the task's own event, or `R.fault` when it holds."""
        self.note(f"{u.name}: {why}: safe-stopped (a reset starts it again)", logging.ERROR)
        if not u.raise_failure(u.clock.now_ns() * 1e-9, why):
            u.supervisor.stop(why, FaultKind.INTERNAL)

    def _runs_task(self, task: str) -> bool:
        """`task` is a Robot-Task of the mission, active where the run is now: its type 3 is its own
        event. Otherwise (the daemon's Hold task, or a task the mission has already stopped) the
        resource faulted with no task of the mission on it: the mission's `R.fault`."""
        mc = self.mission
        runner, mission = mc.runner, mc.mission
        if runner is None or mission is None:
            return False
        tasks = mission.automaton.program.tasks
        return any(tasks[t].name == task for t in runner.active_in(runner.snapshot()))

    def _fault_bit(self, resource: str) -> int:
        """The input bit of the mission's `resource.fault`; 0 if the mission does not declare it."""
        mission = self.mission.mission
        if mission is None:
            return 0
        return dict(mission.automaton.program.fault_inputs).get(resource, 0)

    def _end_on_held_fault(self, why: str) -> None:
        """A resource the mission does not declare safe-stopped: the mission has no input for it,
        so the run ends here, aborted, and every other resource is back on its Hold task at its
        next tick: held where it is, not stopped."""
        others = "; the other resources are held" if len(self.units) > 1 else ""
        self.note(f"run ended: {why}{others}", logging.WARNING)
        self.mission.end(MissionResult.ABORTED)

    def _task_fault(self, task: str) -> Fault | None:
        """What task `task`'s last type 3 was about (set in its tick, before the event was queued)."""
        return next((t.fault for t in self.mission.tasks() if t.name == task), None)

    # ---- commands -------------------------------------------------------------------------
    def command(self, cmd: str, args: dict[str, Any]) -> Result | Pending:
        """Execute one operator command (arguments checked against the table); raise
        `CommandError` (nothing changed) if it cannot be done."""
        spec = COMMANDS.get(cmd)
        if spec is None or spec.where != "rt":
            raise CommandError(f"unknown command {cmd!r} for the real-time process")
        reply: Result | Pending = self.commands.handler(cmd)(**with_defaults(spec, args))
        self.publish()
        return reply


def joint_limits(cfg: RobotConfig) -> list[dict[str, Any]]:
    return [
        {
            "name": j.name,
            "position_min_rad": j.position_min_rad,
            "position_max_rad": j.position_max_rad,
            "max_velocity_rad_s": j.max_velocity_rad_s,
            "max_acceleration_rad_s2": j.max_acceleration_rad_s2,
            "max_torque_nm": j.max_torque_nm,
        }
        for j in cfg.joints
    ]
