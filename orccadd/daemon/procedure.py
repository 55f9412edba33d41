"""The mission's lifecycle in the automaton thread: loaded, started, held, resumed, ended.

It owns the loaded mission and its `Runner`, turns task events into the automaton's inputs,
applies each reaction's actions (per resource, one switch request per reaction: the task the
automaton wants active on it, or its Hold task), and reports the end of a run. It asks each
resource's control thread for switches through its `SwitchingLoop.request_switch` only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from logging import INFO, WARNING
from typing import Any, NamedTuple

from orccadd.automaton import Automaton
from orccadd.daemon.mission import LoadedMission, MissionRunner
from orccadd.daemon.ports import LoopPort, OutputsPort, ResourcePort
from orccadd.daemon.publisher import Publisher
from orccadd.daemon.replies import CommandError
from orccadd.task import RobotTask
from orccadd.wire.schema import MachineState, MissionResult, Trace


class Instant(NamedTuple):
    """One reaction of the automaton: from state s0 to s1 on `inputs`, with `actions` (states as
    the runner snapshots them: a network's are tuples)."""

    s0: Any
    s1: Any
    inputs: int
    actions: int


REACTIONS_PER_INSTANT = 64  # instants the automaton may take on its own (`pause`) in one go
MISSIONS_KEPT = 8  # missions whose names `describe` keeps for the trace


def _bits(mask: int) -> list[int]:
    out = []
    i = 0
    while mask:
        if mask & 1:
            out.append(i)
        mask >>= 1
        i += 1
    return out


class MissionControl:
    def __init__(
        self,
        loops: Sequence[LoopPort],
        publisher: Publisher,
        note: Callable[..., None],
        abort: Callable[[str], None],
    ) -> None:
        self.loops = tuple(loops)  # one per resource, in the robot config's order
        self.loop = loops[0]
        self.hold = loops[0].hold
        self.holds = tuple(lp.hold for lp in loops)
        self._by_resource = {lp.resource.name: i for i, lp in enumerate(loops)}
        self.pub = publisher
        self.note = note
        self._abort = abort  # the supervisor's: safe stop, fault, end of the run
        self.state = MachineState.IDLE
        self.mission: LoadedMission | None = None
        self.runner: MissionRunner | None = None
        self.generation = 0
        self.runs = 0  # runs started since the daemon started (any mission)
        self.loaded: list[dict[str, object]] = []  # the last missions loaded, names for the trace
        self.instants = 0
        self.result = MissionResult.NONE
        # per resource (loop index): the mission task the automaton wants active on it
        self.current: list[RobotTask | None] = [None] * len(self.loops)
        # an output to the cell the instant emitted: (its name, the mission's) to the command
        # daemon at once (the real-time process sets it; the trace says it too, later)
        self.cell_output: Callable[[str, str], None] = lambda name, mission: None
        # per resource's name: the thread that performs its output actions (`emit R.Y`)
        self.outputs: dict[str, OutputsPort] = {}

    @property
    def running(self) -> bool:
        return self.state in (MachineState.RUNNING, MachineState.HOLDING)

    def need(self, *states: MachineState, what: str) -> None:
        if self.state not in states:
            allowed = " or ".join(s.name.lower() for s in states)
            raise CommandError(f"cannot {what} while {self.state.name.lower()} (only when {allowed})")

    def tasks(self) -> list[RobotTask]:
        """The Hold tasks (one per resource), then the mission's tasks: their telemetry ids."""
        return [*self.holds, *(self.mission.tasks if self.mission else ())]

    def loop_of(self, task: RobotTask) -> LoopPort:
        """The control loop of the resource `task` runs on."""
        return self.loops[self._by_resource[task.resource.name]]

    def publish_task_ids(self) -> None:
        tasks = self.tasks()
        for lp in self.loops:
            lp.set_tasks(tasks)
            lp.set_input_events(self._input_events(lp.resource))

    def _input_events(self, resource: ResourcePort) -> tuple[int, ...]:
        return self.input_events_of(resource, self.mission)

    @staticmethod
    def input_events_of(resource: ResourcePort, mission: LoadedMission | None) -> tuple[int, ...]:
        """The event of each of `resource`'s named inputs `mission` declares (`R.X`), -1 else."""
        if mission is None:
            return ()
        p = mission.automaton.program
        by_bit = {bit: eid for eid, bit in mission.event_bits.items()}
        out = []
        for x in resource.description.inputs:
            name = f"{resource.name}.{x}"
            out.append(by_bit.get(1 << p.inputs.index(name), -1) if name in p.inputs else -1)
        return tuple(out)

    # ---- lifecycle ----------------------------------------------------------------------------
    def install(self, loaded: LoadedMission) -> None:
        self.need(MachineState.IDLE, MachineState.READY, what="load a mission")
        self.mission = loaded
        self.publish_task_ids()
        self.generation += 1
        self.pub.mission_gen = self.generation
        self.loaded = [
            *self.loaded[-(MISSIONS_KEPT - 1) :],
            {"generation": self.generation, **loaded.describe()},
        ]
        self.state = MachineState.READY
        self.result = MissionResult.NONE

    def start(self, t_s: float, procedure: str) -> str:
        self.need(MachineState.READY, what="start")
        mission = self.mission
        assert mission is not None
        main = str(mission.describe()["main_procedure"])
        if procedure and procedure != main:
            raise CommandError(
                f"mission {mission.name} has no main procedure {procedure!r} (it has {main!r})"
            )
        self.runner = mission.new_runner()
        self.runs += 1
        self.state = MachineState.RUNNING
        self.result = MissionResult.NONE
        self.note(f"start {mission.name}")
        self.react(t_s, 0)
        return main

    def cell_input(self, name: str, peer: str) -> int:
        """The input bit of `name` from `peer` (a remote input declared `from "peer"`, or the
        peer's loss); 0 without a mission or if it takes no such input from that peer."""
        if self.mission is None:
            return 0
        p = self.mission.automaton.program
        if (name, peer) in p.remote_inputs or (name, peer) in p.lost_inputs:
            return p.input_bit(name)
        return 0

    def operator_input(self, name: str) -> int:
        mission = self.mission
        assert mission is not None
        p = mission.automaton.program
        from_cell = {n: peer for n, peer in (*p.remote_inputs, *p.lost_inputs)}
        if name in from_cell:
            raise CommandError(f"{name} comes from the cell (peer {from_cell[name]!r}), not from `send`")
        ops = [
            n
            for n, k in zip(p.inputs, p.input_kind, strict=True)
            if k == "operator" and "." not in n and n not in from_cell
        ]
        if "." in name and name in p.inputs:
            r = name.split(".", 1)[0]
            raise CommandError(
                f"{name} is resource {r}'s digital input: it comes from the device, not from `send`"
            )
        for op in ops:
            if op == name or op.lower() == name.lower():
                return 1 << p.inputs.index(op)
        raise CommandError(
            f"mission {mission.name} has no operator input {name!r} (it has: {', '.join(ops) or 'none'})"
        )

    def hold_mission(self) -> None:
        self.need(MachineState.RUNNING, what="hold")
        self.state = MachineState.HOLDING
        for lp in self.loops:
            lp.request_switch(lp.hold)
        self.note("hold")

    def resume(self) -> str | None:
        """Back to the tasks the automaton wants active (each restarted from the measured
        state); their names, or None if none runs."""
        self.need(MachineState.HOLDING, what="resume")
        self.state = MachineState.RUNNING
        for lp, task in zip(self.loops, self.current, strict=True):
            if task is not None:
                lp.request_switch(task)
        self.note("resume")
        names = [t.name for t in self.current if t is not None]
        return ", ".join(names) if names else None

    def end(self, result: MissionResult | None = None) -> None:
        """The run is over (or aborted): back to READY (IDLE without a mission), every resource
        on its Hold task."""
        if result is not None and self.running:
            self.result = result
        self.state = MachineState.READY if self.mission else MachineState.IDLE
        self.current = [None] * len(self.loops)
        self.runner = None
        for lp in self.loops:
            if lp.active is not lp.hold:
                lp.request_switch(lp.hold)

    # ---- reactions ----------------------------------------------------------------------------
    def plan(self, inputs: int) -> list[Instant]:
        """The instants a reaction to `inputs` takes, without taking them: the first, then those
        the automaton takes on its own (`pause`), up to the end of the run. Pure: the control
        thread calls it too (`InlineReactor`), under the automaton's lock."""
        runner, mission = self.runner, self.mission
        assert runner is not None and mission is not None
        a = mission.top
        ends = a.success_bit | a.failed_bit | a.safe_done_bit
        s0 = runner.snapshot()
        out = []
        for _ in range(REACTIONS_PER_INSTANT):
            s1, actions = runner.peek(s0, inputs)
            out.append(Instant(s0, s1, inputs, actions))
            if actions & ends or runner.waits(s1):
                break
            s0, inputs = s1, 0
        return out

    def react(self, t_s: float, inputs: int) -> None:
        """One instant of the automaton, then the instants it takes on its own (`pause`)."""
        runner = self.runner
        assert runner is not None
        for instant in self.plan(inputs):
            runner.restore(instant.s1)
            self.book(t_s, instant, request=True)
            if not self.running:
                return

    def book(self, t_s: float, instant: Instant, request: bool) -> None:
        """An instant taken: its trace record, notes, the task it makes active (`request`:
        asked of the control thread; else the control thread switched already, in the tick)."""
        self.instants += 1
        runner = self.runner
        assert runner is not None
        s0, s1 = runner.number(instant.s0), runner.number(instant.s1)
        self.pub.trace(Trace.INSTANT, t_s, 0, s0, s1, _bits(instant.inputs), _bits(instant.actions))
        self._apply(instant.actions, request)

    def target_of(self, state: Any, actions: int) -> list[tuple[RobotTask | None, bool]] | None:
        """Per resource (loop index): the mission task the automaton makes active on it in
        `state`, reached with `actions` (None: none, or the run ends), and whether it (re)starts;
        None if two tasks would be active on one resource. Pure: the control threads call it too
        (`InlineReactor`)."""
        mission, runner = self.mission, self.runner
        assert mission is not None and runner is not None
        a = mission.top
        out: list[tuple[RobotTask | None, bool]] = [(None, False)] * len(self.loops)
        if actions & (a.success_bit | a.failed_bit | a.safe_done_bit):
            return out
        starts = a.starts(actions)
        for i in runner.active_in(state):
            task = mission.tasks[i]
            k = self._by_resource[task.resource.name]
            if out[k][0] is not None:
                return None
            out[k] = (task, bool(starts >> i & 1))
        return out

    def _outputs(self, a: Automaton, actions: int) -> None:
        """The resources' output actions the instant emits (`emit R.Y`), in declaration order,
        each queued to its resource's output thread (this thread never waits on a device; one
        that fails is a fault of its resource, `OutputWorker`)."""
        cell = a.program.cell_outputs
        for k, name in enumerate(a.program.internals):
            if cell and name in cell and actions >> (a.emit_base + k) & 1:
                self.cell_output(name, a.program.name)
            if "." in name and actions >> (a.emit_base + k) & 1:
                r, y = name.split(".", 1)
                worker = self.outputs.get(r)
                if worker is None:  # the compiler checks the names: never, but said if so
                    self.note(f"output {name} not performed: no output thread for {r!r}", WARNING)
                else:
                    worker.request(y)

    def _apply(self, actions: int, request: bool = True) -> None:
        mission, runner = self.mission, self.runner
        assert mission is not None and runner is not None
        a = mission.top
        state = runner.snapshot()
        decided = self.target_of(state, actions)
        if decided is None:  # the verifier excludes it; activation asserts it again
            names = ", ".join(mission.tasks[i].name for i in runner.active_in(state))
            self._abort(f"activation refused: {names} would be active at once on one resource")
            return
        ended = actions & (a.success_bit | a.failed_bit | a.safe_done_bit)
        if a.stops(actions) or a.starts(actions):
            self.note(", ".join(a.describe_actions(actions)))
        if actions & a.safe_bit:
            self.note("entering the safe procedure", WARNING)
        self._outputs(a, actions)
        self.current = [target for target, _ in decided]
        if request and self.state is not MachineState.HOLDING:
            for lp, (target, restart) in zip(self.loops, decided, strict=True):
                want = target if target is not None else lp.hold
                if want is not lp.active or restart:
                    lp.request_switch(want)
        if ended:
            result = (
                MissionResult.SUCCESS
                if actions & a.success_bit
                else MissionResult.FAILED
                if actions & a.failed_bit
                else MissionResult.SAFE
            )
            level = INFO if result is MissionResult.SUCCESS else WARNING
            self.note(f"mission {mission.name} ended: {result.name.lower()}", level)
            self.end(result)
