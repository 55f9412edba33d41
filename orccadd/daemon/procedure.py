"""The mission's lifecycle in the automaton thread: loaded, started, held, resumed, ended.

It owns the loaded mission and its `Runner`, turns task events into the automaton's inputs,
applies each reaction's actions (one switch request per reaction: stops, then the task the
automaton wants active), and reports the end of a run. It asks the control thread for switches
through `SwitchingLoop.request_switch` only.
"""

from __future__ import annotations

from collections.abc import Callable
from logging import INFO, WARNING
from typing import NamedTuple

from orccadd.automaton import Runner
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.mission import LoadedMission
from orccadd.daemon.publisher import Publisher
from orccadd.daemon.replies import CommandError
from orccadd.task import RobotTask
from orccadd.wire.schema import MachineState, MissionResult, Trace


class Instant(NamedTuple):
    """One reaction of the automaton: from state s0 to s1 on `inputs`, with `actions`."""

    s0: int
    s1: int
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
        loop: SwitchingLoop,
        publisher: Publisher,
        note: Callable[..., None],
        abort: Callable[[str], None],
    ) -> None:
        self.loop = loop
        self.hold = loop.hold
        self.pub = publisher
        self.note = note
        self._abort = abort  # the supervisor's: safe stop, fault, end of the run
        self.state = MachineState.IDLE
        self.mission: LoadedMission | None = None
        self.runner: Runner | None = None
        self.generation = 0
        self.runs = 0  # runs started since the daemon started (any mission)
        self.loaded: list[dict[str, object]] = []  # the last missions loaded, names for the trace
        self.instants = 0
        self.result = MissionResult.NONE
        self.current: RobotTask | None = None  # the mission task the automaton wants active

    @property
    def running(self) -> bool:
        return self.state in (MachineState.RUNNING, MachineState.HOLDING)

    def need(self, *states: MachineState, what: str) -> None:
        if self.state not in states:
            allowed = " or ".join(s.name.lower() for s in states)
            raise CommandError(f"cannot {what} while {self.state.name.lower()} (only when {allowed})")

    def tasks(self) -> list[RobotTask]:
        """The Hold task, then the mission's tasks (telemetry ids 0, 1, ...)."""
        return [self.hold, *(self.mission.tasks if self.mission else ())]

    # ---- lifecycle ----------------------------------------------------------------------------
    def install(self, loaded: LoadedMission) -> None:
        self.need(MachineState.IDLE, MachineState.READY, what="load a mission")
        self.loop.set_mission_tasks(loaded.tasks)
        self.mission = loaded
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
        self.runner = Runner(mission.automaton)
        self.runs += 1
        self.state = MachineState.RUNNING
        self.result = MissionResult.NONE
        self.note(f"start {mission.name}")
        self.react(t_s, 0)
        return main

    def operator_input(self, name: str) -> int:
        mission = self.mission
        assert mission is not None
        p = mission.automaton.program
        ops = [n for n, k in zip(p.inputs, p.input_kind, strict=True) if k == "operator"]
        for op in ops:
            if op == name or op.lower() == name.lower():
                return 1 << p.inputs.index(op)
        raise CommandError(
            f"mission {mission.name} has no operator input {name!r} (it has: {', '.join(ops) or 'none'})"
        )

    def hold_mission(self) -> None:
        self.need(MachineState.RUNNING, what="hold")
        self.state = MachineState.HOLDING
        self.loop.request_switch(self.hold)
        self.note("hold")

    def resume(self) -> str | None:
        self.need(MachineState.HOLDING, what="resume")
        self.state = MachineState.RUNNING
        if self.current is not None:
            self.loop.request_switch(self.current)  # restarts from the measured state
        self.note("resume")
        return self.current.name if self.current else None

    def end(self, result: MissionResult | None = None) -> None:
        """The run is over (or aborted): back to READY (IDLE without a mission), on the Hold task."""
        if result is not None and self.running:
            self.result = result
        self.state = MachineState.READY if self.mission else MachineState.IDLE
        self.current = None
        self.runner = None
        if self.loop.active is not self.hold:
            self.loop.request_switch(self.hold)

    # ---- reactions ----------------------------------------------------------------------------
    def plan(self, inputs: int) -> list[Instant]:
        """The instants a reaction to `inputs` takes, without taking them: the first, then those
        the automaton takes on its own (`pause`), up to the end of the run. Pure: the control
        thread calls it too (`InlineReactor`), under the automaton's lock."""
        runner, mission = self.runner, self.mission
        assert runner is not None and mission is not None
        a = mission.automaton
        ends = a.success_bit | a.failed_bit | a.safe_done_bit
        s0 = runner.state
        out = []
        for _ in range(REACTIONS_PER_INSTANT):
            s1, actions = runner.peek(s0, inputs)
            out.append(Instant(s0, s1, inputs, actions))
            if actions & ends:
                break
            nxt = runner.table[s1].get(0)
            if nxt is None or (nxt[0] == s1 and nxt[1] == 0):
                break
            s0, inputs = s1, 0
        return out

    def react(self, t_s: float, inputs: int) -> None:
        """One instant of the automaton, then the instants it takes on its own (`pause`)."""
        runner = self.runner
        assert runner is not None
        for instant in self.plan(inputs):
            runner.state = instant.s1
            self.book(t_s, instant, request=True)
            if not self.running:
                return

    def book(self, t_s: float, instant: Instant, request: bool) -> None:
        """An instant taken: its trace record, notes, the task it makes active (`request`:
        asked of the control thread; else the control thread switched already, in the tick)."""
        self.instants += 1
        self.pub.trace(
            Trace.INSTANT, t_s, 0, instant.s0, instant.s1, _bits(instant.inputs), _bits(instant.actions)
        )
        self._apply(instant.actions, request)

    def target_of(self, state: int, actions: int) -> tuple[RobotTask | None, bool] | None:
        """The mission task the automaton makes active in `state`, reached with `actions` (None
        once the run ends), and whether it (re)starts; None if two tasks would be active. Pure:
        the control thread calls it too (`InlineReactor`)."""
        mission = self.mission
        assert mission is not None
        a = mission.automaton
        active = a.active[state]
        if len(set(active)) > 1:
            return None
        if not active or actions & (a.success_bit | a.failed_bit | a.safe_done_bit):
            return None, False
        return mission.tasks[active[0]], bool(a.starts(actions) >> active[0] & 1)

    def _apply(self, actions: int, request: bool = True) -> None:
        mission, runner = self.mission, self.runner
        assert mission is not None and runner is not None
        a = mission.automaton
        decided = self.target_of(runner.state, actions)
        if decided is None:  # the verifier excludes it; activation asserts it again
            names = ", ".join(mission.tasks[i].name for i in sorted(set(a.active[runner.state])))
            self._abort(f"activation refused: {names} would be active at once")
            return
        target, restart = decided
        ended = actions & (a.success_bit | a.failed_bit | a.safe_done_bit)
        if a.stops(actions) or a.starts(actions):
            self.note(", ".join(a.describe_actions(actions)))
        if actions & a.safe_bit:
            self.note("entering the safe procedure", WARNING)
        self.current = target
        if request and self.state is not MachineState.HOLDING:
            want = target if target is not None else self.hold
            if want is not self.loop.active or restart:
                self.loop.request_switch(want)
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
