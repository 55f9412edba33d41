"""The execution machine (seed §5.1–5.3): the automaton thread's side of the real-time process.

It owns the loaded mission and its `Runner`, turns the control thread's events into the
automaton's inputs, applies the reaction's actions (stops, then starts: one switch request per
reaction), and executes the operator's commands. It runs in the highest-priority thread and
never blocks on a client: commands arrive already parsed, replies are small dictionaries.

Every command either succeeds or changes nothing and says why (`CommandError`).
"""

from __future__ import annotations

import time
from enum import IntEnum
from pathlib import Path
from typing import Any

from orccadd.automaton import Runner
from orccadd.config.robot import RobotConfig
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.mission import LoadedMission, load_mission
from orccadd.daemon.telemetry import TRACE_IDX, S, TelemetryBlock, Trace
from orccadd.errors import OrccaddError, ParameterError
from orccadd.physres.base import PhysicalResource, Status
from orccadd.runtime.clock import Clock
from orccadd.task import EventQueue, EventRegistry, RobotTask, build_task, load_task_file
from orccadd.task.events import EventKind


class MachineState(IntEnum):
    IDLE = 0  # no mission loaded: the Hold task holds the arm
    READY = 1  # a verified mission is loaded, not running
    RUNNING = 2
    HOLDING = 3  # the mission is suspended; the Hold task holds the arm


class MissionResult(IntEnum):
    NONE = 0
    SUCCESS = 1
    SAFE = 2  # the safe procedure ran to its end
    FAILED = 3  # a type 3 exception inside the safe procedure
    ABORTED = 4  # the operator aborted
    STOPPED = 5  # shut down (SIGTERM) while running


class Command(IntEnum):
    """Operator actions, as recorded in the trace."""

    LOAD = 1
    START = 2
    STOP = 3
    ABORT = 4
    HOLD = 5
    RESUME = 6
    RESET = 7
    TUNE = 8
    SEND = 9
    INJECT = 10
    SHUTDOWN = 11


class CommandError(OrccaddError):
    """A command that cannot be done now (the message says why); nothing was changed."""


def _bits(mask: int) -> list[int]:
    out = []
    i = 0
    while mask:
        if mask & 1:
            out.append(i)
        mask >>= 1
        i += 1
    return out


RESET_WAIT_S = 2.0  # longest wait for a device to leave its fault after a reset (bus round trips)
MAX_INJECTED_MS = 5000.0  # longest injected tick: a stall, not a hang


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
        self.registry = EventRegistry()
        self.queue = EventQueue(4096)
        self.hold = build_task(
            load_task_file(cfg.resolve(cfg.daemon.hold_task)), resource, self.registry, self.queue
        )
        blend = int(round(cfg.daemon.switch_blend_s / cfg.control_period_s))
        self.loop = SwitchingLoop(
            resource,
            clock,
            self.hold,
            self.queue,
            telemetry,
            wake_fd,
            overrun_limit=cfg.daemon.overrun_limit,
            blend_ticks=blend,
        )
        self.allow_fault_injection = allow_fault_injection
        self.state = MachineState.IDLE
        self.mission: LoadedMission | None = None
        self.runner: Runner | None = None
        self.generation = 0
        self.instants = 0
        self.result = MissionResult.NONE
        self.fault = ""  # why the resource was safe-stopped ("" when not)
        self.current: RobotTask | None = None  # the mission task the automaton wants active
        self.log: list[str] = []  # recent notable happenings (bounded), for `status`
        self.publish()

    # ---- helpers ------------------------------------------------------------------------
    def now_s(self) -> float:
        return self.clock.now_ns() * 1e-9

    def note(self, msg: str) -> None:
        self.log = [*self.log[-49:], f"{time.strftime('%H:%M:%S')} {msg}"]

    def publish(self) -> None:
        self.tel.write_status(
            {
                S.MACHINE: float(self.state),
                S.AUTOMATON_STATE: float(self.runner.state if self.runner else -1),
                S.MISSION_GEN: float(self.generation),
                S.INSTANTS: float(self.instants),
                S.RESULT: float(self.result),
                S.FAULTED: 1.0 if self.fault else 0.0,
                S.PLANT_PID: float(getattr(getattr(self.resource, "process", None), "pid", 0) or 0),
            }
        )

    def trace(
        self,
        kind: Trace,
        t_s: float,
        code: int = 0,
        s_from: int = -1,
        s_to: int = -1,
        inputs: list[int] | None = None,
        actions: list[int] | None = None,
    ) -> None:
        rec = self.tel.begin_trace()
        rec[1] = kind
        rec[2] = t_s
        rec[3] = time.time()
        rec[4] = s_from
        rec[5] = s_to
        rec[6] = code
        ins = (inputs or [])[:TRACE_IDX]
        acts = (actions or [])[:TRACE_IDX]
        rec[7] = len(ins)
        rec[8] = len(acts)
        rec[9 : 9 + len(ins)] = ins
        rec[9 + TRACE_IDX : 9 + TRACE_IDX + len(acts)] = acts
        self.tel.commit_trace(rec)

    def task_names(self) -> list[str]:
        """Telemetry task ids: 0 is Hold, k the mission's task k-1."""
        tasks = self.mission.tasks if self.mission else ()
        return [self.hold.name, *(t.name for t in tasks)]

    def describe(self) -> dict[str, Any]:
        return {
            "robot": self.cfg.name,
            "config": self.cfg.source,
            "dof": self.cfg.dof,
            "joints": list(self.cfg.joint_names),
            "period_s": self.cfg.control_period_s,
            "telemetry": self.tel.name,
            "plant_channel": getattr(getattr(self.resource, "channel", None), "name", None),
            "generation": self.generation,
            "tasks": self.task_names(),
            "events": self.registry.names(),
            "mission": self.mission.describe() if self.mission else None,
            "log": self.log[-10:],
            "fault": self.fault,
        }

    # ---- events from the control thread ---------------------------------------------------
    def on_events(self) -> None:
        mission = self.mission
        inputs = 0
        t_last = 0.0
        for t_s, eid in self.queue.drain():
            bit = mission.event_bits.get(eid, 0) if mission and self.state is not MachineState.READY else 0
            info = self.registry.info(eid)
            if info.kind is EventKind.T3 and not self.fault:
                self.fault = f"{info.name} ({self.resource.fault_message or 'safe stop'})"
                self.note(f"type 3: {info.name}: safe stop")
            if bit and self.state in (MachineState.RUNNING, MachineState.HOLDING):
                inputs |= bit
                t_last = t_s
            else:
                self.trace(Trace.EVENT, t_s, code=eid)
        if inputs:
            self.react(t_last, inputs)
        self.publish()

    def react(self, t_s: float, inputs: int) -> None:
        """One instant of the automaton, then the instants it takes on its own (`pause`)."""
        runner, mission = self.runner, self.mission
        assert runner is not None and mission is not None
        for _ in range(64):
            s0 = runner.state
            actions = runner.react(inputs)
            self.instants += 1
            self.trace(Trace.INSTANT, t_s, 0, s0, runner.state, _bits(inputs), _bits(actions))
            self.apply(actions)
            if self.state not in (MachineState.RUNNING, MachineState.HOLDING):
                return
            nxt = runner.table[runner.state].get(0)
            if nxt is None or (nxt[0] == runner.state and nxt[1] == 0):
                return
            inputs = 0

    def apply(self, actions: int) -> None:
        mission = self.mission
        assert mission is not None
        a = mission.automaton
        stops, starts = a.stops(actions), a.starts(actions)
        active = set(a.active[self.runner.state]) if self.runner else set()
        if len(active) > 1:  # the verifier excludes it; activation asserts it again
            names = ", ".join(mission.tasks[i].name for i in sorted(active))
            self.abort(f"activation refused: {names} would be active at once")
            return
        ended = actions & (a.success_bit | a.failed_bit | a.safe_done_bit)  # masks
        target = mission.tasks[next(iter(active))] if active and not ended else None
        restart = target is not None and bool(starts >> mission.tasks.index(target) & 1)
        if stops or starts:
            self.note(", ".join(a.describe_actions(actions)))
        if actions & a.safe_bit:
            self.note("entering the safe procedure")
        self.current = target
        if self.state is not MachineState.HOLDING:
            want = target if target is not None else self.hold
            if want is not self.loop.active or restart:
                self.loop.request_switch(want)
        if ended:
            self.result = (
                MissionResult.SUCCESS
                if actions & a.success_bit
                else MissionResult.FAILED
                if actions & a.failed_bit
                else MissionResult.SAFE
            )
            self.note(f"mission {mission.name} ended: {self.result.name.lower()}")
            self.end_mission()

    def end_mission(self) -> None:
        self.state = MachineState.READY if self.mission else MachineState.IDLE
        self.current = None
        self.runner = None
        if self.loop.active is not self.hold:
            self.loop.request_switch(self.hold)

    # ---- commands -------------------------------------------------------------------------
    def command(self, cmd: str, args: dict[str, Any]) -> dict[str, Any]:
        """Execute one operator command; raise `CommandError` (nothing changed) if it cannot be."""
        handler = getattr(self, f"cmd_{cmd}", None)
        if handler is None:
            raise CommandError(f"unknown command {cmd!r}")
        reply: dict[str, Any] = handler(**args)
        self.publish()
        return reply

    def _need(self, *states: MachineState, what: str) -> None:
        if self.state not in states:
            allowed = " or ".join(s.name.lower() for s in states)
            raise CommandError(f"cannot {what} while {self.state.name.lower()} (only when {allowed})")

    def cmd_describe(self) -> dict[str, Any]:
        return self.describe()

    def cmd_load(self, path: str) -> dict[str, Any]:
        self._need(MachineState.IDLE, MachineState.READY, what="load a mission")
        if not Path(path).is_file():
            raise CommandError(f"{path}: no such mission file")
        try:
            loaded = load_mission(path, self.resource, self.registry, self.queue)
        except OrccaddError as e:
            raise CommandError(str(e)) from None
        for i, t in enumerate(loaded.tasks, start=1):
            self.loop.task_ids[id(t)] = i
        self.mission = loaded
        self.generation += 1
        self.state = MachineState.READY
        self.result = MissionResult.NONE
        self.trace(Trace.COMMAND, self.now_s(), Command.LOAD)
        self.note(f"loaded mission {loaded.name} ({loaded.automaton.n_states} states, all checks passed)")
        return {"mission": loaded.describe(), "report": loaded.report.format()}

    def cmd_start(self, procedure: str = "") -> dict[str, Any]:
        self._need(MachineState.READY, what="start")
        if self.fault:
            raise CommandError(f"the arm was safe-stopped ({self.fault}): `reset` first")
        mission = self.mission
        assert mission is not None
        main = mission.describe()["main_procedure"]
        if procedure and procedure != main:
            raise CommandError(
                f"mission {mission.name} has no main procedure {procedure!r} (it has {main!r})"
            )
        self.runner = Runner(mission.automaton)
        self.state = MachineState.RUNNING
        self.result = MissionResult.NONE
        t = self.now_s()
        self.trace(Trace.COMMAND, t, Command.START)
        self.note(f"start {mission.name}")
        self.react(t, 0)
        return {"started": main}

    def operator_input(self, name: str) -> int:
        mission = self.mission
        assert mission is not None
        p = mission.automaton.program
        ops = [n for n, k in zip(p.inputs, p.input_kind, strict=True) if k == "operator"]
        for op in ops:
            if op == name or op.lower() == name.lower():
                return 1 << mission.automaton.program.inputs.index(op)
        raise CommandError(
            f"mission {mission.name} has no operator input {name!r} (it has: {', '.join(ops) or 'none'})"
        )

    def cmd_send(self, input: str) -> dict[str, Any]:
        self._need(MachineState.RUNNING, MachineState.HOLDING, what="send an input")
        bit = self.operator_input(input)
        t = self.now_s()
        self.trace(Trace.COMMAND, t, Command.SEND)
        self.react(t, bit)
        return {"sent": input}

    def cmd_stop(self) -> dict[str, Any]:
        """Graceful: the mission's own `Stop` operator input (the procedure's defined stop)."""
        self._need(MachineState.RUNNING, MachineState.HOLDING, what="stop")
        try:
            bit = self.operator_input("Stop")
        except CommandError as e:
            raise CommandError(f"{e}; the mission defines no graceful stop: use `abort`") from None
        if self.state is MachineState.HOLDING:
            self.cmd_resume()
        t = self.now_s()
        self.trace(Trace.COMMAND, t, Command.STOP)
        self.react(t, bit)
        return {"stopped": self.state is not MachineState.RUNNING, "state": self.state.name.lower()}

    def abort(self, why: str) -> None:
        self.resource.safe_stop()
        self.fault = self.fault or why
        if self.state in (MachineState.RUNNING, MachineState.HOLDING):
            self.result = MissionResult.ABORTED
        self.note(f"abort: {why}")
        self.end_mission()

    def cmd_abort(self) -> dict[str, Any]:
        self.trace(Trace.COMMAND, self.now_s(), Command.ABORT)
        self.abort("aborted by the operator")
        return {"aborted": True}

    def cmd_hold(self) -> dict[str, Any]:
        self._need(MachineState.RUNNING, what="hold")
        self.state = MachineState.HOLDING
        self.loop.request_switch(self.hold)
        self.trace(Trace.COMMAND, self.now_s(), Command.HOLD)
        self.note("hold")
        return {"holding": True}

    def cmd_resume(self) -> dict[str, Any]:
        self._need(MachineState.HOLDING, what="resume")
        self.state = MachineState.RUNNING
        if self.current is not None:
            self.loop.request_switch(self.current)  # restarts from the measured state
        self.trace(Trace.COMMAND, self.now_s(), Command.RESUME)
        self.note("resume")
        return {"resumed": self.current.name if self.current else None}

    def cmd_reset(self) -> dict[str, Any]:
        if not (self.fault or self.resource.stopping_or_stopped):
            return {"reset": False, "detail": "nothing to reset"}
        if self.state in (MachineState.RUNNING, MachineState.HOLDING):
            raise CommandError("the mission is still running (its safe procedure): stop or abort it first")
        if not self.resource.state.status & Status.STOPPED:
            raise CommandError("the safe stop is still under way: wait until the arm is at rest")
        try:
            if hasattr(self.resource, "reset_fault"):
                self.resource.reset_fault()
                # the control thread's next reads show whether the device left its fault
                end = time.monotonic() + max(100 * self.cfg.control_period_s, RESET_WAIT_S)
                while self.resource.state.status & Status.FAULT and time.monotonic() < end:
                    time.sleep(self.cfg.control_period_s)
            self.resource.clear_stop()
        except OrccaddError as e:
            raise CommandError(str(e)) from None
        self.fault = ""
        self.loop.request_switch(self.hold)
        self.trace(Trace.COMMAND, self.now_s(), Command.RESET)
        self.note("reset: stop cleared, holding")
        return {"reset": True}

    def _task(self, name: str) -> RobotTask:
        tasks = [self.hold, *(self.mission.tasks if self.mission else ())]
        for t in tasks:
            if t.name == name:
                return t
        raise CommandError(f"no task {name!r} (tasks: {', '.join(t.name for t in tasks)})")

    def cmd_params(self, task: str = "") -> dict[str, Any]:
        tasks = [self._task(task)] if task else [self.hold, *(self.mission.tasks if self.mission else ())]
        return {"params": {t.name: t.parameters() for t in tasks}}

    def cmd_tune(self, path: str, value: Any) -> dict[str, Any]:
        parts = path.split(".")
        if len(parts) != 3:
            raise CommandError(f"{path!r}: a parameter is named TASK.MODULE.PARAM (see `params`)")
        task = self._task(parts[0])
        rest = f"{parts[1]}.{parts[2]}"
        old = next((p["value"] for p in task.parameters() if p["name"] == rest), None)
        try:
            # a task the control thread is not (about to be) ticking takes the value at once
            idle = task is not self.loop.active and task is not self.loop.pending_task
            task.tune(rest, value, now=idle)
        except ParameterError as e:
            raise CommandError(str(e)) from None
        self.trace(Trace.COMMAND, self.now_s(), Command.TUNE)
        self.note(f"tune {path} = {value}")
        return {"tuned": path, "value": value, "previous": old}

    def cmd_inject(self, fault: str, ticks: int = 20, extra_ms: float = 0.0) -> dict[str, Any]:
        """Fault injection for commissioning and tests (only with --allow-fault-injection)."""
        if not self.allow_fault_injection:
            raise CommandError("fault injection is disabled (start orccadd with --allow-fault-injection)")
        self.trace(Trace.COMMAND, self.now_s(), Command.INJECT)
        if fault == "resource":
            inject = getattr(self.resource, "inject_fault", None)
            if inject is None:
                raise CommandError(f"resource {self.resource.name!r} cannot inject faults")
            inject("injected fault")
        elif fault == "overrun":
            if not 0.0 <= extra_ms <= MAX_INJECTED_MS:
                raise CommandError(f"inject: extra_ms (={extra_ms:g}) must be in [0, {MAX_INJECTED_MS:g}]")
            period_ms = self.cfg.control_period_s * 1e3
            self.loop.busy_ns = int((extra_ms or 1.5 * period_ms) * 1e6)
            self.loop.busy_ticks = max(1, min(int(ticks), 10_000))
        else:
            raise CommandError(f"unknown fault {fault!r} (faults: resource, overrun)")
        self.note(f"injected fault: {fault}")
        return {"injected": fault}
