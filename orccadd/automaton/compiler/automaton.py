"""The compiled Robot-Procedure: an immutable explicit automaton (`runtime.runner` steps it).

At run time a reaction is one masked dictionary lookup: `table[state][inputs & relevant[state]]`
gives `(next state, action bits)`. Action bits are ordered so that decoding them in bit order gives
stops before starts (the switching order of seed §5.1: the old law stops, the new one starts).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from orccadd.automaton.language.program import Program

MAIN, SAFE, END = 0, 1, 2  # phases of a state
STANDS_FOR_LIMIT = 64  # input sets a row is copied under at most (see `Automaton.stands_for`)
PHASE_NAMES = ("main", "safe", "end")


@dataclass(frozen=True)
class Automaton:
    """States are 0..n-1, the initial state is 0. Never mutated after `compile_program`."""

    program: Program
    relevant: tuple[int, ...]  # per state: the input bits its reactions depend on
    table: tuple[Mapping[int, tuple[int, int]], ...]  # per state: masked inputs -> (next, actions)
    active: tuple[tuple[int, ...], ...]  # per state: the Robot-Tasks active (indices, sorted)
    phase: tuple[int, ...]
    where: tuple[str, ...]  # per state: what the program waits for, with source lines
    action_names: tuple[str, ...]
    # action bit layout
    stop_base: int
    start_base: int
    emit_base: int
    success_bit: int
    safe_bit: int
    failed_bit: int
    safe_done_bit: int
    # per input index, the input bit standing for it in the table: its event class's representative
    # (orccadd/automaton/compiler/classes.py; an operator input stands for itself)
    event_rep: tuple[int, ...] = ()

    @property
    def n_states(self) -> int:
        return len(self.table)

    def __reduce__(self) -> tuple[Any, tuple[dict[str, Any]]]:
        """Pickled with plain dict rows (the daemon compiles in a child process), read-only again
        once unpickled."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        fields["table"] = tuple(dict(row) for row in self.table)
        return (_unpickle, (fields,))

    @property
    def n_transitions(self) -> int:
        return sum(len(t) for t in self.table)

    def react(self, state: int, inputs: int) -> tuple[int, int]:
        """(next state, action bits) for the inputs present in this instant (any inputs: reduced to
        the environment model by `normalize` when they are not a row of the table as they are)."""
        row = self.table[state]
        hit = row.get(inputs & self.relevant[state])
        return hit if hit is not None else row[self.normalize(state, inputs)]

    def stands_for(self, inputs: int, limit: int = STANDS_FOR_LIMIT) -> list[int]:
        """The input sets a row's inputs stand for: each class representative replaced by each
        event of its class (`event_rep`), in every combination; just `[inputs]` when there would
        be more than `limit` (events of several tasks in one instant: `normalize` maps them)."""
        out = [0]
        i = 0
        while inputs >> i:
            if inputs >> i & 1:
                rep = 1 << i
                members = [1 << j for j, r in enumerate(self.event_rep) if r == rep] or [rep]
                if len(out) * len(members) > limit:
                    return [inputs]
                out = [x | m for x in out for m in members]
            i += 1
        return out

    def describe_actions(self, actions: int) -> list[str]:
        return [self.action_names[i] for i in range(len(self.action_names)) if actions >> i & 1]

    def starts(self, actions: int) -> int:
        n = len(self.program.tasks)
        return (actions >> self.start_base) & ((1 << n) - 1)

    def stops(self, actions: int) -> int:
        n = len(self.program.tasks)
        return (actions >> self.stop_base) & ((1 << n) - 1)

    def normalize(self, state: int, inputs: int) -> int:
        """Reduce raw inputs to the environment model the table was built for: operator inputs kept,
        one resource's fault (the first) where no active task runs on it (not in the first instant),
        events only from active tasks, at most one per task (T3 > T2 > post > pre > sync), each
        event standing as its class's representative (`event_rep`)."""
        from orccadd.automaton.language.program import PRIORITY

        p = self.program
        out = inputs & p.operator_mask
        faults = inputs & (p.faults_possible(self.active[state]) if state else 0)
        out |= faults & -faults  # one resource's fault per instant: the first
        for t in set(self.active[state]):
            present = inputs & p.event_masks[t] & self.relevant[state]
            if not present:
                continue
            best = min(
                (ev for ev in p.tasks[t].events if ev[2] & present),
                key=lambda ev: PRIORITY[ev[0]],
            )
            bit = best[2]
            out |= self.event_rep[bit.bit_length() - 1] if self.event_rep else bit
        return out & self.relevant[state]


def _unpickle(fields: dict[str, Any]) -> Automaton:
    fields["table"] = tuple(MappingProxyType(row) for row in fields["table"])
    return Automaton(**fields)
