"""The law switch in the tick of its event, with each unit in a process of its own.

In one process, a control thread takes the automaton's reaction itself (`inline.InlineReactor`:
a table lookup under the automaton's lock). A unit process has no automaton. So the automaton
thread computes, whenever it is idle and its state has changed, each unit's reactions ahead:
per event the unit's tasks (or its inputs) can raise in a tick, the task every unit of the
station switches to (`ReactionTables.publish`), written into the unit's channel. A tick that
raises one such event takes it (`ChannelReactor.react`): under the station's try-lock (a
`flock` the automaton's work holds, a tick only tries), if the automaton has consumed every
earlier event of every unit, it switches its own law in this tick, posts the other units'
switches in their channels (their next tick), records what it took and invalidates every
table. The automaton thread then books it (`ReactionTables.book`: the same instants, from the
same state: the trace, the notes, the end of the run) and publishes anew.

Otherwise — two events in one tick, a type 3, the automaton busy or behind, no table yet —
nothing happens in the tick, and the automaton thread reacts as always (the switch one tick
later). Same outcome either way: only when it is what the automaton thread would do.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from orccadd.daemon.mission import LoadedMission
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.unitshm import NO_TASK, TryLock, UnitChannel
from orccadd.task import RobotTask
from orccadd.task.events import EventKind, EventRegistry
from orccadd.wire.schema import MachineState

MEMO_MAX = 4096  # automaton states whose tables are kept


class ReactionTables:
    """The automaton thread's side (`Machine.reactor` when the units are processes)."""

    def __init__(
        self,
        mission: MissionControl,
        registry: EventRegistry,
        channels: Sequence[UnitChannel],
        lock: TryLock,
        task_id: Callable[[RobotTask], int],
    ) -> None:
        self.mission = mission
        self.registry = registry
        self.channels = tuple(channels)  # one per resource, in the station's order
        self.lock = lock
        self.task_id = task_id  # a task's index in the units' task lists (-1: none)
        self.upto = [0] * len(self.channels)  # per unit: events before this index were reacted to
        self.inline = 0  # reactions taken in the tick of their event
        self._published: Any = None  # what the tables were computed from
        self._memo: dict[Any, list[list[tuple[int, list[float]]]]] = {}  # by that, this mission's
        self._memo_generation = -1

    @contextmanager
    def held(self) -> Iterator[None]:
        """The automaton thread at work: no tick takes a reaction meanwhile. What they took is
        booked first; the tables are published anew at the end."""
        self.lock.acquire()
        try:
            self.book()
            yield
            self.publish()
        finally:
            self.lock.release()

    def book(self) -> None:
        """The reactions units took in a tick, booked (lock held)."""
        mc = self.mission
        for k, ch in enumerate(self.channels):
            taken = ch.taken()
            if taken is None:
                continue
            event_id, t_s, _, end = taken
            self.upto[k] = end
            self.inline += 1
            self._published = None
            if mc.mission is None or mc.runner is None:
                continue
            plan = mc.plan(mc.mission.event_bits.get(event_id, 0))
            mc.runner.restore(plan[-1].s1)
            for instant in plan:
                mc.book(t_s, instant, request=False)

    def publish(self) -> None:
        """Each unit's reactions from the automaton's present state, if it is running and has
        consumed every event (lock held); otherwise none."""
        mc = self.mission
        mission, runner = mc.mission, mc.runner
        ready = mc.state is MachineState.RUNNING and mission is not None and runner is not None
        ready = ready and all(ch.drained() for ch in self.channels)
        if not ready or mission is None or runner is None:
            self._published = None
            for ch in self.channels:
                ch.invalidate()
            return
        key = (mc.generation, runner.number(runner.snapshot()), tuple(ch.wanted_task for ch in self.channels))
        if key == self._published:
            return
        self._published = key
        if key[0] != self._memo_generation or len(self._memo) >= MEMO_MAX:  # another mission; or full
            self._memo, self._memo_generation = {}, key[0]
        rows = self._memo.get(key)
        if rows is None:  # a state seen before (a mission's loop) costs a lookup, not the plans
            rows = self._memo[key] = self._rows(mission)
        for ch, unit_rows in zip(self.channels, rows, strict=True):
            ch.publish(unit_rows)

    def _rows(self, mission: LoadedMission) -> list[list[tuple[int, list[float]]]]:
        """Per unit, its events' reactions from the automaton's present state."""
        mc = self.mission
        rows: list[list[tuple[int, list[float]]]] = [[] for _ in self.channels]
        by_resource = {lp.resource.name: k for k, lp in enumerate(mc.loops)}
        inputs = {eid: k for k, lp in enumerate(mc.loops) for eid in mc.input_events_of(lp.resource, mission)}
        for event_id, bit in mission.event_bits.items():
            info = self.registry.info(event_id)
            if info.kind is EventKind.T3:
                continue
            k = inputs.get(event_id)
            if k is None:
                task = next((t for t in mission.tasks if t.name == info.task), None)
                if task is None:
                    continue
                k = by_resource[task.resource.name]
            tasks = self._decide(bit)
            if tasks is not None:
                rows[k].append((event_id, tasks))
        return rows

    def _decide(self, inputs: int) -> list[float] | None:
        """Per unit, the task the reaction to `inputs` switches it to (`NO_TASK`: none), as
        `MissionControl._apply` would request it; None if a tick may not take it."""
        mc = self.mission
        wants = [NO_TASK] * len(self.channels)
        for instant in mc.plan(inputs):
            decided = mc.target_of(instant.s1, instant.actions)
            if decided is None:
                return None
            for k, (lp, (target, restart)) in enumerate(zip(mc.loops, decided, strict=True)):
                task = target if target is not None else lp.hold
                index = self.task_id(task)
                if index != self.channels[k].wanted_task or restart:
                    wants[k] = float(index)
        return wants


class ChannelReactor:
    """A unit process's control thread taking its tick's event's reaction (`TickReactor`)."""

    def __init__(self, channels: Sequence[UnitChannel], index: int, lock: TryLock) -> None:
        self.channels = tuple(channels)  # every unit's, in the station's order
        self.own = self.channels[index]
        self.index = index
        self.lock = lock
        self.tasks: list[RobotTask] = []  # by index, as the automaton numbers them
        self.inline = 0
        self.deferred = 0

    def react(
        self,
        loop: Any,
        t_s: float,
        first: int,
        end: int,
        active: RobotTask,
        switch: Callable[[RobotTask], None],
    ) -> bool:
        own = self.own
        if end - first != 1 or not own.has_table():  # one event this tick, and a table
            return False
        if not self.lock.try_acquire():
            self.deferred += 1
            return False
        try:
            others = (ch for i, ch in enumerate(self.channels) if i != self.index)
            if own.consumed != first or not all(ch.drained() for ch in others):  # the automaton is behind
                self.deferred += 1
                return False
            event_id = int(own.ring[first % own.ring_len][1])
            row = own.row_of(event_id)
            if row is None:
                return False
            for ch in self.channels:
                ch.invalidate()
            mine = float(row[1 + self.index])
            own.take(event_id, t_s, first, end, mine)
            for k, ch in enumerate(self.channels):
                task = float(row[1 + k])
                if task == NO_TASK or k == self.index:
                    continue
                ch.request_switch(int(task), fresh=False)
            if mine != NO_TASK:
                tasks = self.tasks
                index = int(mine)
                switch(tasks[index] if 0 <= index < len(tasks) else loop.hold)
            self.inline += 1
            return True
        finally:
            self.lock.release()
