"""The law switch in the tick of its event: the control thread takes the automaton's reaction.

A tick's law raises an event the mission listens to (a postcondition, a type 2 exception, a
synchronisation signal). The automaton's reaction to it is a table lookup, so the control thread
takes it itself, between the law's `compute` and the command's `commit`, switches to the task the
automaton makes active, and that law computes this tick's command from this tick's measurement:
the switch takes effect in the tick of the event (0 periods, where the automaton thread's path
takes 1: it hears the event after the tick has written its command).

Only when that is the same as what the automaton thread would do:

- the automaton thread is idle: it holds `lock` whenever it works (`held()`); the control thread
  only tries it, never waits;
- it is up to date: every earlier event consumed, every earlier switch request applied, every
  earlier inline reaction booked;
- the mission is running (not held), and no event of the tick is a type 3 exception (the safe
  stop and the supervisor's fault are the automaton thread's), and no instant would activate two
  tasks (the supervisor's abort).

With several resources (one control thread each), "up to date" covers all of them: no event
pending in any resource's queue but this tick's, every resource's switch requests applied. The
reaction's switch on this resource takes effect in this tick; those it makes on the others are
requested of their control threads, which apply them at their next tick.

Otherwise nothing happens here and the automaton thread reacts as before (the switch one tick
later). Afterwards the automaton thread books what was taken here (trace records, notes, the end
of the run, `MissionControl.book`) and leaves the events reacted to out of its own reactions
(`upto`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.procedure import Instant, MissionControl
from orccadd.task import RobotTask
from orccadd.task.events import EventKind, EventRegistry
from orccadd.wire.schema import MachineState

Switch = Callable[[RobotTask], None]


class InlineReactor:
    def __init__(self, mission: MissionControl, registry: EventRegistry) -> None:
        self.lock = threading.Lock()
        self.mission = mission
        self.registry = registry
        self.loops = mission.loops
        self.taken: list[tuple[float, Instant]] = []  # reacted in a tick, not booked yet
        # per resource (loop index): the events before this queue index were reacted to in their tick
        self.upto = [0] * len(self.loops)
        self.inline = 0  # reactions taken in the tick of their event
        self.deferred = 0  # left to the automaton thread (busy or behind)

    # ---- the automaton thread -------------------------------------------------------------
    @contextmanager
    def held(self) -> Iterator[None]:
        """The automaton thread at work: the control threads react to nothing meanwhile. What
        they took before is booked first, so the work starts from the automaton's true state."""
        with self.lock:
            self.book()
            yield

    def book(self) -> None:
        """Book the instants taken in a tick (lock held)."""
        taken, self.taken = self.taken, []
        for t_s, instant in taken:
            self.mission.book(t_s, instant, request=False)

    # ---- a control thread (tick-safe: a try-lock, table lookups) ----------------------------
    def react(
        self,
        loop: SwitchingLoop,
        t_s: float,
        first: int,
        end: int,
        active: RobotTask,
        switch: Switch,
    ) -> bool:
        """React to the events `first` ≤ index < `end` of this tick of `loop`, if it can be done
        here (see the module's docstring); `switch(task)` makes `task` active on `loop`'s
        resource (under the lock, before the automaton thread can look). True if taken."""
        if not self.lock.acquire(blocking=False):
            self.deferred += 1
            return False
        try:
            if self.taken or not self._up_to_date(loop, first):
                self.deferred += 1
                return False
            decision = self._decide(loop, first, end)
            if decision is None:
                return False
            plan, wants = decision
            runner = self.mission.runner
            assert runner is not None
            runner.restore(plan[-1].s1)
            self.taken.extend((t_s, instant) for instant in plan)
            self.upto[self.loops.index(loop)] = end
            self.inline += 1
            for lp, want in zip(self.loops, wants, strict=True):
                if want is None:
                    continue
                if lp is loop:
                    switch(want)
                else:
                    lp.request_switch(want)
            return True
        finally:
            self.lock.release()

    def _up_to_date(self, loop: SwitchingLoop, first: int) -> bool:
        """Every earlier event consumed (this loop's before `first`, the others' all), every
        switch request applied."""
        for lp in self.loops:
            pending = lp.queue.tail != (first if lp is loop else lp.queue.pushed)
            if pending or not lp.requests_applied():
                return False
        return True

    def _decide(
        self, loop: SwitchingLoop, first: int, end: int
    ) -> tuple[list[Instant], list[RobotTask | None]] | None:
        mc = self.mission
        mission = mc.mission
        if mission is None or mc.runner is None or mc.state is not MachineState.RUNNING:
            return None
        inputs = 0
        queue = loop.queue
        for i in range(first, end):
            eid = queue.event_at(i)
            if self.registry.info(eid).kind is EventKind.T3:
                return None
            inputs |= mission.event_bits.get(eid, 0)
        if not inputs:
            return None
        plan = mc.plan(inputs)
        # per resource, as `MissionControl._apply` would request: the last instant's wins
        wants: list[RobotTask | None] = [None] * len(self.loops)
        for instant in plan:
            decided = mc.target_of(instant.s1, instant.actions)
            if decided is None:
                return None
            for k, (lp, (target, restart)) in enumerate(zip(self.loops, decided, strict=True)):
                task = target if target is not None else lp.hold
                if task is not lp.active or restart:
                    wants[k] = task
        return plan, wants
