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
from dataclasses import replace
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.daemon.commands import RtCommands, describe_resource
from orccadd.daemon.inline import InlineReactor
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.publisher import Publisher
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.daemon.supervision import Supervisor
from orccadd.fault import Fault
from orccadd.physres.base import PhysicalResource
from orccadd.runtime.clock import Clock
from orccadd.task import EventQueue, EventRegistry, build_task, load_task_file
from orccadd.task.events import EventKind
from orccadd.wire.commands import COMMANDS, Dispatcher, with_defaults
from orccadd.wire.schema import S, Trace
from orccadd.wire.telemetry import TelemetryBlock

log = logging.getLogger("orccadd.machine")
NOTES_KEPT = 50


class Machine:
    """Missions, the automaton and commands. Methods run in the automaton thread only."""

    def __init__(
        self,
        cfg: RobotConfig,
        resource: PhysicalResource,
        clock: Clock,
        telemetry: TelemetryBlock,
        wake_fd: int,
        *,
        allow_fault_injection: bool = False,
    ) -> None:
        self.cfg = cfg
        self.resource = resource
        self.clock = clock
        self.tel = telemetry
        self.pub = Publisher(telemetry)
        self.registry = EventRegistry()
        self.queue = EventQueue(4096)
        hold_spec = load_task_file(cfg.resolve(cfg.daemon.hold_task))
        # the daemon's own task holds for as long as nothing else commands the arm
        hold_spec = replace(hold_spec, task=replace(hold_spec.task, timeout_s=float("inf")))
        hold = build_task(hold_spec, resource, self.registry, self.queue)
        self.loop = SwitchingLoop(
            resource,
            clock,
            hold,
            self.queue,
            telemetry,
            wake_fd,
            overrun_limit=cfg.daemon.overrun_limit,
            blend_ticks=int(round(cfg.daemon.switch_blend_s / cfg.control_period_s)),
        )
        self.allow_fault_injection = allow_fault_injection
        self.notes: list[str] = []  # recent notable happenings (bounded), for `describe`
        self.mission = MissionControl(self.loop, self.pub, self.note, self._abort)
        self.reactor = InlineReactor(self.mission, self.registry, self.queue)
        self.loop.reactor = self.reactor
        self.supervisor = Supervisor(cfg, resource, self.loop, self.mission, self.note)
        self.supervisor.on_cause = lambda n: self.pub.trace(Trace.FAULT, self.now_s(), code=n)
        self.rt_commands = RtCommands(self)
        self.commands = Dispatcher(self.rt_commands, "rt")
        self.publish()

    def _abort(self, why: str) -> None:
        self.supervisor.abort(why)

    # ---- helpers ------------------------------------------------------------------------
    def now_s(self) -> float:
        return self.clock.now_ns() * 1e-9

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
                S.AUTOMATON_STATE: float(mc.runner.state if mc.runner else -1),
                S.MISSION_GEN: float(mc.generation),
                S.INSTANTS: float(mc.instants),
                S.RESULT: float(mc.result),
                S.FAULTED: float(self.supervisor.faults) if self.supervisor.fault else 0.0,
                S.HELPER_PID: float(self.resource.helper_pid()),
            }
        )

    def describe(self) -> dict[str, Any]:
        mc = self.mission
        return {
            "robot": self.cfg.name,
            "config": self.cfg.source,
            "dof": self.cfg.dof,
            "joints": list(self.cfg.joint_names),
            # the limits the controller enforces, per joint (SI units in the keys)
            "joint_limits": [
                {
                    "name": j.name,
                    "position_min_rad": j.position_min_rad,
                    "position_max_rad": j.position_max_rad,
                    "max_velocity_rad_s": j.max_velocity_rad_s,
                    "max_acceleration_rad_s2": j.max_acceleration_rad_s2,
                    "max_torque_nm": j.max_torque_nm,
                }
                for j in self.cfg.joints
            ],
            "period_s": self.cfg.control_period_s,
            "telemetry": self.tel.name,
            "resource": describe_resource(self),
            "generation": mc.generation,
            "tasks": [t.name for t in mc.tasks()],
            "hold_tunables": mc.hold.tunable_names,  # the Hold task's (task id 0 of a tune record)
            "events": self.registry.names(),
            "event_kinds": [k.name.lower() for k in self.registry.kinds()],  # post, t1, t2, t3, sync, pre
            "mission": mc.mission.describe() if mc.mission else None,
            "missions": mc.loaded,  # the last ones loaded: the trace names its records by them
            "log": self.notes[-10:],
            "fault": self.supervisor.fault.to_wire() if self.supervisor.fault else None,
            "faults": self.supervisor.recent(),
        }

    # ---- events from the control thread ---------------------------------------------------
    def on_events(self) -> None:
        """The control thread's events: type 3 to the supervisor, the rest to the automaton,
        but for those it reacted to in their tick (`InlineReactor`: booked here)."""
        self.reactor.book()
        mc = self.mission
        mission = mc.mission
        inputs = 0
        t_last = 0.0
        index, upto = self.queue.tail, self.reactor.upto
        for t_s, eid in self.queue.drain():
            info = self.registry.info(eid)
            if info.kind is EventKind.T3:
                self.supervisor.on_t3(info.name, self._task_fault(info.task))
            bit = mission.event_bits.get(eid, 0) if mission is not None and mc.running else 0
            reacted = index < upto
            index += 1
            if bit:
                if not reacted:
                    inputs |= bit
                    t_last = t_s
            else:
                self.pub.trace(Trace.EVENT, t_s, code=eid)
        if inputs:
            mc.react(t_last, inputs)
        self.publish()

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
