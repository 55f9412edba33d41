"""Steps a `Network` (network.py): the context's automaton and the branch automata of its `par`.

An instant is one lookup in the context. Where the context's reaction depends on the par's
completion code (the row holds one reaction per code), the branches react first, each by its own
lookup, but only those an input of the instant concerns (each input belongs to one branch) or
that move on their own; the others stay paused. The par's code is the max of its branches'
(Esterel). The context's actions then say whether the instant takes the branches' reactions
(`step_bit`) and whether it kills what is left of them (`kill_bit`: their running tasks stop, a
task started in this instant is not started).
"""

from __future__ import annotations

from typing import Any

from orccadd.automaton.network import Network

DONE_I, PAUSED_I = 0, 1  # code indices (`Network.codes` is ordered: done, paused, the exits)
# A branch instant left out of its table (not causal; network.py): computed ahead of the
# context's lookup, it only matters if the context takes it.
_NO_REACTION = (-1, 0)


class NetworkRunner:
    """`Runner`'s interface: `react(inputs)` → action bits, for the highest-priority thread."""

    __slots__ = (
        "alive",
        "branch_mask",
        "brel",
        "brows",
        "btasks",
        "busy",
        "busy_states",
        "ended",
        "hole_classes",
        "hole_mask",
        "kill_bit",
        "low",
        "n_alive",
        "net",
        "orel",
        "orows",
        "ostate",
        "owner",
        "shift",
        "start_base",
        "step_bit",
        "stop_base",
        "st",
    )

    def __init__(self, net: Network) -> None:
        self.net = net
        ctx = net.context
        code_base = len(net.program.inputs)
        real = (1 << code_base) - 1
        self.orel = tuple(r & real for r in ctx.relevant)
        par_bits = net.step_bit | net.kill_bit
        self.orows = tuple(_context_row(ctx.stands_for, row, code_base, len(net.codes), par_bits) for row in ctx.table)
        self.alive = net.hole_alive
        self.hole_classes = net.hole_classes
        self.hole_mask = sum(bits for bits, _ in net.hole_classes)
        self.shift = net.code_shift
        self.low = (1 << net.code_shift) - 1
        self.step_bit, self.kill_bit = net.step_bit, net.kill_bit
        self.start_base, self.stop_base = ctx.start_base, ctx.stop_base
        self.brows = tuple(
            tuple({x: hit for key, hit in row.items() for x in b.stands_for(key)} for row in b.table)
            for b in net.branches
        )
        self.brel = tuple(b.relevant for b in net.branches)
        self.btasks = tuple(b.active for b in net.branches)
        self.ended = tuple(b.n_states - 1 for b in net.branches)
        self.busy_states = tuple(
            frozenset(s for s, row in enumerate(b.table) if s and row.get(0, (s, PAUSED_I << self.shift)) != (s, PAUSED_I << self.shift))
            for b in net.branches
        )
        self.owner: dict[int, int] = {}
        for i, bits in enumerate(net.split.inputs):
            while bits:
                low = bits & -bits
                self.owner[low] = i
                bits ^= low
        self.branch_mask = sum(net.split.inputs)
        self.ostate = 0
        self.st = [0] * len(net.branches)
        self.n_alive = 0
        self.busy: set[int] = set()

    @property
    def state(self) -> tuple[int, ...]:
        return (self.ostate, *self.st)

    def react(self, inputs: int) -> int:
        """Inputs present in this instant → action bits. Never raises for inputs outside the model."""
        os = self.ostate
        key = inputs & self.orel[os]
        h = inputs & self.hole_mask
        if h:
            for bits, rep in self.hole_classes:
                if h & bits:
                    key |= rep
        row = self.orows[os]
        hit = row.get(key)
        if hit is None:  # inputs outside the environment model: reduced to it
            hit = row[self.net.context.normalize(os, inputs) & self.orel[os] | _hole_part(self.hole_classes, h)]
        if type(hit) is not list:
            self.ostate = hit[0]
            return int(hit[1])
        code, moves = self._par(inputs, self.alive[os])
        self.ostate, actions = hit[code]
        out = actions & ~(self.step_bit | self.kill_bit)
        if actions & self.step_bit:
            out = self._take(moves, out, code)
        if actions & self.kill_bit:
            out = self._kill_all(out)
        return out

    def _par(self, inputs: int, alive: bool) -> tuple[int, list[tuple[int, int, int]]]:
        """The par's code index in this instant, and each reacting branch's (index, next, actions)."""
        st = self.st
        if alive:
            touched = set(self.busy)
            x = inputs & self.branch_mask
            while x:
                low = x & -x
                touched.add(self.owner[low])
                x ^= low
            states = [(b, st[b]) for b in touched if st[b] != self.ended[b]]
            top = PAUSED_I if self.n_alive > len(states) else DONE_I
        else:
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

    def _take(self, moves: list[tuple[int, int, int]], out: int, code: int) -> int:
        st = self.st
        for b, nxt, actions in moves:
            if nxt < 0:  # the verifier refuses a mission that can get here (network.py)
                raise RuntimeError(f"branch {b} of the par has no reaction in state {st[b]}")
            st[b] = nxt
            out |= actions
            if nxt in self.busy_states[b]:
                self.busy.add(b)
            else:
                self.busy.discard(b)
        self.n_alive = sum(1 for b, s in enumerate(st) if s != self.ended[b])
        if code == PAUSED_I:
            return out
        if code > PAUSED_I:  # a branch exits: the others are killed
            out = self._kill_all(out)
        self._reset()
        return out

    def _kill_all(self, out: int) -> int:
        for b, s in enumerate(self.st):
            for t in self.btasks[b][s]:
                started = 1 << (self.start_base + t)
                out = out & ~started if out & started else out | 1 << (self.stop_base + t)
        self._reset()
        return out

    def _reset(self) -> None:
        self.st = [0] * len(self.st)
        self.n_alive = 0
        self.busy.clear()


def _hole_part(classes: tuple[tuple[int, int], ...], h: int) -> int:
    key = 0
    for bits, rep in classes:
        if h & bits:
            key |= rep
    return key


def _context_row(stands_for: Any, row: Any, code_base: int, n_codes: int, par_bits: int) -> dict[int, Any]:
    """A context row keyed by its real inputs: (next, actions), or a list of them indexed by the
    par's code where they differ or touch the par; each key also under every input set it stands
    for."""
    real = (1 << code_base) - 1
    by_real: dict[int, dict[int, tuple[int, int]]] = {}
    for key, hit in row.items():
        by_real.setdefault(key & real, {})[key >> code_base] = hit
    out: dict[int, Any] = {}
    for key, hits in by_real.items():
        values = set(hits.values())
        one = next(iter(values))
        plain = len(values) == 1 and not one[1] & par_bits
        merged: Any = one if plain else [hits.get(i, one) for i in range(n_codes)]
        for x in stands_for(key):
            out[x] = merged
    return out
