"""Steps a `Network` (compiler/network.py): the context's automaton and the branch automata of its `par`.

An instant is one lookup in the context. Where the context's reaction depends on the par's
completion code (the row holds one reaction per code), the branches react first, each by its own
lookup, but only those an input of the instant concerns (each input belongs to one branch) or
that move on their own; the others stay paused. The par's code is the max of its branches'
(Esterel). The context's actions then say whether the instant takes the branches' reactions
(`step_bit`; `fresh_bit`: the par starts in this instant, its code is the branches' first
instants'), and whether it kills what is left of them (`kill_bit`: their running tasks stop, one
they started in this instant is not started; `kill_first_bit`: killed, then started afresh, a
loop around a preemption). A kill works on the branches' own actions, apart from the context's
(which may start one of those tasks again in the same instant: the safe procedure).
"""

from __future__ import annotations

import copy
from typing import Any

from orccadd.automaton.compiler.automaton import Automaton
from orccadd.automaton.compiler.network import Network

NetState = tuple[int, tuple[int, ...], int, int, int, frozenset[int]]
DONE_I, PAUSED_I = 0, 1  # code indices (`Network.codes` is ordered: done, paused, the exits)
# A branch instant left out of its table (not causal; compiler/network.py): computed ahead of the
# context's lookup, it only matters if the context takes it.
_NO_REACTION = (-1, 0)


class NetworkRunner:
    """`Runner`'s interface: `react(inputs)` → action bits, for the highest-priority thread."""

    __slots__ = (
        "alive",
        "binputs",
        "branch_mask",
        "brel",
        "brows",
        "btasks",
        "busy",
        "busy_states",
        "ended",
        "fault_mask",
        "fresh_bit",
        "hole_classes",
        "hole_mask",
        "kill_bit",
        "kill_first_bit",
        "low",
        "n_alive",
        "net",
        "operator_mask",
        "orel",
        "orows",
        "ostate",
        "owner",
        "plain",
        "present",
        "running",
        "running_events",
        "scratch",
        "shift",
        "st",
        "start_actions",
        "start_after",
        "start_base",
        "start_code",
        "start_moves",
        "start_rel",
        "state_events",
        "step_bit",
        "stop_base",
        "task_fault",
        "task_mask",
    )

    def __init__(self, net: Network) -> None:
        self.net = net
        self.scratch: NetworkRunner | None = None  # for `peek`
        ctx = net.context
        code_base = len(net.program.inputs)
        real = (1 << code_base) - 1
        hole_mask = sum(bits for bits, _ in net.hole_classes)
        # where the par is, a branch task's event counts through its class (`_hole_part`) only
        self.orel = tuple(
            r & real & ~(hole_mask if net.hole_present[s] else 0) for s, r in enumerate(ctx.relevant)
        )
        n_codes = len(net.codes)
        self.orows = tuple(
            _context_row(ctx.stands_for, row, code_base, n_codes, net.step_bit) for row in ctx.table
        )
        self.alive = net.hole_alive
        self.present = net.hole_present
        self.hole_classes = net.hole_classes
        self.hole_mask = hole_mask
        self.shift = net.code_shift
        self.low = (1 << net.code_shift) - 1
        self.step_bit, self.kill_bit = net.step_bit, net.kill_bit
        self.kill_first_bit, self.fresh_bit = net.kill_first_bit, net.fresh_bit
        self.plain = ~(net.step_bit | net.kill_bit | net.kill_first_bit | net.fresh_bit)
        self.start_base, self.stop_base = ctx.start_base, ctx.stop_base
        self.brows = tuple(
            tuple({x: hit for key, hit in row.items() for x in b.stands_for(key)} for row in b.table)
            for b in net.branches
        )
        self.brel = tuple(b.relevant for b in net.branches)
        self.btasks = tuple(b.active for b in net.branches)
        self.ended = tuple(b.n_states - 1 for b in net.branches)
        self.busy_states = tuple(_busy_states(b, self.shift) for b in net.branches)
        self.owner: dict[int, int] = {}
        for i, bits in enumerate(net.split.inputs):
            while bits:
                low = bits & -bits
                self.owner[low] = i
                bits ^= low
        self.branch_mask = sum(net.split.inputs)
        self.operator_mask = net.program.operator_mask
        p = net.program
        self.fault_mask = p.fault_mask  # a resource's fault, raised only while no task runs on it
        faults = dict(p.fault_inputs)
        self.task_fault = tuple(faults.get(t.resource, 0) for t in p.tasks)  # task t → its resource's
        self.binputs = net.split.inputs
        self.task_mask = tuple(tuple(sum(1 << t for t in act) for act in b.active) for b in net.branches)
        self.ostate = 0
        self.st = [0] * len(net.branches)
        self.n_alive = 0
        self.running = 0  # the tasks the branches run (bit t: task t)
        self.running_events = 0  # and the events they may raise
        self.state_events = tuple(
            tuple(sum(net.program.event_masks[t] for t in set(act)) for act in b.active) for b in net.branches
        )
        self.busy: set[int] = set()
        self.start_moves: list[tuple[int, int, int]] | None = None
        self.start_rel = 0  # the inputs the branches' first instants test
        for rel in self.brel:
            self.start_rel |= rel[0]
        # with none of those inputs, the par starts the same way every time: precomputed
        self.start_code, moves = self._par(0, alive=False)
        if self.start_code == PAUSED_I:
            self.start_actions = self._take(moves, PAUSED_I)
            self.start_after = (
                tuple(self.st),
                self.n_alive,
                self.running,
                self.running_events,
                frozenset(self.busy),
            )
            self._reset()
            self.start_moves = moves

    def restart(self) -> None:
        """Back to the initial state (a new run of the mission; the tables are kept)."""
        self.ostate = 0
        self._reset()

    @property
    def state(self) -> tuple[int, ...]:
        """The context's state, then each branch's (0 before the par starts and after it ends)."""
        return (self.ostate, *self.st)

    @property
    def phase(self) -> int:
        return self.net.context.phase[self.ostate]

    def active(self) -> tuple[int, ...]:
        """The Robot-Tasks active now (the context's and the branches'), sorted."""
        out = list(self.net.context.active[self.ostate])
        if self.alive[self.ostate]:
            for b, s in enumerate(self.st):
                out.extend(self.btasks[b][s])
        return tuple(sorted(out))

    # the stepping interface the daemon drives a mission by (`Runner`'s): a state is a snapshot
    def snapshot(self) -> NetState:
        """Where the network is: the context's state, each branch's, what they run."""
        return (
            self.ostate,
            tuple(self.st),
            self.n_alive,
            self.running,
            self.running_events,
            frozenset(self.busy),
        )

    def restore(self, state: NetState) -> None:
        ostate, st, self.n_alive, self.running, self.running_events, busy = state
        self.ostate, self.st, self.busy = ostate, list(st), set(busy)

    def peek(self, state: NetState, inputs: int) -> tuple[NetState, int]:
        """The reaction of `state` to `inputs`, (next state, action bits), without taking it
        (on a scratch runner sharing the tables: this one stays where it is)."""
        scratch = self.scratch
        if scratch is None:
            scratch = self.scratch = copy.copy(self)
        scratch.restore(state)
        actions = scratch.react(inputs)
        return scratch.snapshot(), actions

    def active_in(self, state: NetState) -> tuple[int, ...]:
        """The Robot-Tasks active in `state` (task indices, a task once)."""
        out = set(self.net.context.active[state[0]])
        if self.alive[state[0]]:
            for b, s in enumerate(state[1]):
                out.update(self.btasks[b][s])
        return tuple(sorted(out))

    def waits(self, state: NetState) -> bool:
        """`state` reacts to no input by staying as it is, doing nothing: it waits for one."""
        nxt, actions = self.peek(state, 0)
        return nxt == state and actions == 0

    def number(self, state: NetState) -> int:
        """The state as the trace records it: the context's."""
        return state[0]

    def react(self, inputs: int) -> int:
        """Inputs present in this instant → action bits. Never raises for inputs outside the model."""
        out: int
        os = self.ostate
        if inputs & self.fault_mask:  # one at most, of a resource no branch's task runs on
            faults = inputs & self.fault_mask & ~(self._busy_faults() if self.running else 0)
            inputs = inputs & ~self.fault_mask | faults & -faults
        key = inputs & self.orel[os]
        h = inputs & self.hole_mask if self.present[os] else 0
        if h:  # only events of the tasks the branches run (the environment model; as `normalize`)
            h &= self.running_events
            key |= _hole_part(self.hole_classes, h)
        row = self.orows[os]
        hit = row.get(key)
        if hit is None:  # inputs outside the environment model: reduced to it
            key = self.net.context.normalize(os, inputs) & self.orel[os]
            hit = row[key | _hole_part(self.hole_classes, h)]
        if type(hit) is not list:  # the par's code does not matter (the par may be killed)
            self.ostate, actions = hit
            if actions & self.kill_bit:
                return actions & self.plain | self._kill_all(0)  # type: ignore[no-any-return]
            return actions  # type: ignore[no-any-return]
        if hit[0][1] & self.fresh_bit:  # the par starts afresh (perhaps just killed: a loop)
            code, moves = self._par(inputs, alive=False)
            self.ostate, actions = hit[code]
            out = actions & self.plain
            if actions & self.kill_first_bit:
                out |= self._kill_all(0)
            branches = self._take(moves, code)
            return out | (self._kill_all(branches) if actions & self.kill_bit else branches)
        if self.alive[os] and not self.busy:
            x = inputs & self.branch_mask
            if not x:  # nothing concerns the branches: each stays paused as it is (one at least)
                self.ostate, actions = hit[PAUSED_I]
                out = actions & self.plain
                return out | self._kill_all(0) if actions & self.kill_bit else out
            b = self.owner[x & -x]
            if not x & ~self.binputs[b]:  # one branch concerned: its lookup, inline
                return self._one(b, inputs, hit)
        code, moves = self._par(inputs, self.alive[os])
        self.ostate, actions = hit[code]
        branches = self._take(moves, code) if actions & self.step_bit else 0
        if actions & self.kill_bit:
            branches = self._kill_all(branches)
        return actions & self.plain | branches  # type: ignore[no-any-return]

    def _one(self, b: int, inputs: int, hit: list[tuple[int, int]]) -> int:
        """The instant when the inputs concern branch b alone (the others stay paused): the
        common case (a task of one branch ends), written out."""
        st = self.st
        s = st[b]
        bhit = self.brows[b][s].get(inputs & self.brel[b][s])
        if bhit is None or s == self.ended[b]:
            code, moves = self._par(inputs, True)
        else:
            nxt, bact = bhit
            ci = bact >> self.shift
            if ci == PAUSED_I or (ci == DONE_I and self.n_alive > 1):
                self.ostate, actions = hit[PAUSED_I]
                branches = 0
                if actions & self.step_bit:
                    tasks = self.task_mask[b]
                    self.running = self.running & ~tasks[s] | tasks[nxt]
                    events = self.state_events[b]
                    self.running_events = self.running_events & ~events[s] | events[nxt]
                    st[b] = nxt
                    branches = bact & self.low
                    if ci == DONE_I:
                        self.n_alive -= 1
                    elif nxt in self.busy_states[b]:
                        self.busy.add(b)
                if actions & self.kill_bit:
                    branches = self._kill_all(branches)
                return actions & self.plain | branches  # type: ignore[no-any-return]
            code, moves = ci, [(b, nxt, bact & self.low)]
        self.ostate, actions = hit[code]
        branches = self._take(moves, code) if actions & self.step_bit else 0
        if actions & self.kill_bit:
            branches = self._kill_all(branches)
        return actions & self.plain | branches  # type: ignore[no-any-return]

    def _par(self, inputs: int, alive: bool) -> tuple[int, list[tuple[int, int, int]]]:
        """The par's code index in this instant, and each reacting branch's (index, next, actions)."""
        st, ended = self.st, self.ended
        if alive:
            touched = list(self.busy)
            x = inputs & self.branch_mask
            while x:
                low = x & -x
                b = self.owner[low]
                if b not in touched:
                    touched.append(b)
                x ^= low
            states = [(b, st[b]) for b in touched if st[b] != ended[b]]
            top = PAUSED_I if self.n_alive > len(states) else DONE_I
        else:
            # the par starts: its tasks' events can only be those of activations running at the
            # start of the instant (killed in it, then started afresh: a loop)
            inputs &= self.operator_mask | self.running_events
            if self.start_moves is not None and not inputs & self.start_rel:
                return self.start_code, self.start_moves
            states = [(b, 0) for b in range(len(st))]
            top = DONE_I
        moves = []
        for b, s in states:
            row = self.brows[b][s]
            hit = row.get(inputs & self.brel[b][s])
            if hit is None:
                hit = row.get(self.net.branches[b].normalize(s, inputs), _NO_REACTION)
            ci = hit[1] >> self.shift if hit[0] >= 0 else PAUSED_I
            moves.append((b, hit[0], hit[1] & self.low))
            if ci > top:
                top = ci
        return top, moves

    def _take(self, moves: list[tuple[int, int, int]], code: int) -> int:
        """The branches take their reactions: their actions (a par that ends or exits is reset;
        one that exits kills the branches still paused)."""
        st, ended, tasks = self.st, self.ended, self.task_mask
        branches = 0
        if moves is self.start_moves:  # the par starts as always: the outcome is precomputed
            after, self.n_alive, self.running, self.running_events, busy = self.start_after
            self.st, self.busy = list(after), set(busy)
            branches = self.start_actions
        else:
            if not self.n_alive:  # the par starts: every branch moves from its first state
                self.n_alive = len(st)
            for b, nxt, actions in moves:
                if nxt < 0:  # the verifier refuses a mission that can get here (compiler/network.py)
                    raise RuntimeError(f"branch {b} of the par has no reaction in state {st[b]}")
                self.running = self.running & ~tasks[b][st[b]] | tasks[b][nxt]
                events = self.state_events[b]
                self.running_events = self.running_events & ~events[st[b]] | events[nxt]
                st[b] = nxt
                branches |= actions
                if nxt == ended[b]:
                    self.n_alive -= 1
                if nxt in self.busy_states[b]:
                    self.busy.add(b)
                else:
                    self.busy.discard(b)
        if code == PAUSED_I:
            return branches
        if code > PAUSED_I:  # a branch exits: the others are killed
            return self._kill_all(branches)
        self._reset()
        return branches

    def _busy_faults(self) -> int:
        """The faults of the resources the branches' running tasks run on."""
        out, running = 0, self.running
        while running:
            low = running & -running
            out |= self.task_fault[low.bit_length() - 1]
            running ^= low
        return out

    def _kill_all(self, branches: int) -> int:
        """Every branch is killed: its running tasks stop; one started in this instant (in
        `branches`, the branches' own actions of this instant) is not started."""
        running = self.running
        started = branches >> self.start_base & running
        branches &= ~(started << self.start_base)
        branches |= (running & ~started) << self.stop_base
        self._reset()
        return branches

    def _reset(self) -> None:
        self.st = [0] * len(self.st)
        self.n_alive = 0
        self.running = 0
        self.running_events = 0
        self.busy.clear()


def _busy_states(b: Automaton, shift: int) -> frozenset[int]:
    """A branch's states that move on their own: with no input they do not stay paused as they are."""
    out = set()
    for s, row in enumerate(b.table[:-1]):  # not the first (not started) nor the last (ended)
        idle = (s, PAUSED_I << shift)
        if s and row.get(0, idle) != idle:
            out.add(s)
    return frozenset(out)


def _hole_part(classes: tuple[tuple[int, int], ...], h: int) -> int:
    key = 0
    for bits, rep in classes:
        if h & bits:
            key |= rep
    return key


def _context_row(stands_for: Any, row: Any, code_base: int, n_codes: int, step_bit: int) -> dict[int, Any]:
    """A context row keyed by its real inputs: (next, actions), or a list of them indexed by the
    par's code where they differ or step the par; each key also under every input set it stands
    for."""
    real = (1 << code_base) - 1
    by_real: dict[int, dict[int, tuple[int, int]]] = {}
    for key, hit in row.items():
        by_real.setdefault(key & real, {})[key >> code_base] = hit
    out: dict[int, Any] = {}
    for key, hits in by_real.items():
        values = set(hits.values())
        one = next(iter(values))
        plain = len(values) == 1 and not one[1] & step_bit
        merged: Any = one if plain else [hits.get(i, one) for i in range(n_codes)]
        for x in stands_for(key):
            out[x] = merged
    return out
