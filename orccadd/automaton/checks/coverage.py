"""Which statements of a mission its reachable reactions execute: the dead-code check's evidence.

The elaborator records each `Site` (a task activation, an `emit`, the start of a branch) with the
kernel term that starts it. Here a copy of the program gets a *probe* before each such term, an
`emit` of a bit above the program's own internal signals, that nothing tests; the copy is then
replayed along every transition of the compiled automaton with the kernel's own `step` (the
internal signals' statuses taken from the transition's actions, the one consistent solution). A
site is executed when its probe is emitted in some reachable reaction; a task activation, when
some reachable state has it running (a task started and preempted in one instant never ran). The
replay is checked against the automaton (same internal signals, same phases): a disagreement is a
`CoverageError`.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from orccadd.automaton.compiler.automaton import END, MAIN, SAFE, Automaton
from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.ast import Loc
from orccadd.automaton.language.program import Site


class CoverageError(Exception):
    """The replay of the probed program disagrees with the automaton (a bug, not the mission's)."""


def executed_sites(a: Automaton) -> set[int]:
    """Indices (in `a.program.sites`) of the sites some reachable reaction executes. A site whose
    term is `nothing` cannot be followed and counts as executed."""
    p = a.program
    base = len(p.internals)
    probes: dict[int, int] = {}  # id of a site's term -> its probe bits
    for i, site in enumerate(p.sites):
        if site.term is not K.NOTHING:
            probes[id(site.term)] = probes.get(id(site.term), 0) | 1 << (base + i)
    main, safe = _probed(p.main, probes), _probed(p.safe, probes)
    runs = {(s.term.task, s.term.loc) for s in p.sites if s.kind == "task" and isinstance(s.term, K.Run)}
    every_probe = 0
    for bits in probes.values():
        every_probe |= bits
    want = _Wanted(every_probe, runs)
    fired, running = _replay(a, main, safe, want)
    fired >>= base
    return {i for i, site in enumerate(p.sites) if _executed(site, fired >> i & 1, running)}


def _executed(site: Site, fired: int, running: set[tuple[int, Loc]]) -> bool:
    if site.term is K.NOTHING:
        return True
    if site.kind == "task" and isinstance(site.term, K.Run):
        return (site.term.task, site.term.loc) in running
    return bool(fired)


@dataclass(frozen=True)
class _Wanted:
    """What the replay looks for: once it has seen all of it, the rest cannot add anything."""

    probes: int
    running: set[tuple[int, Loc]]


def _replay(a: Automaton, main: K.Term, safe: K.Term, want: _Wanted) -> tuple[int, set[tuple[int, Loc]]]:
    """Every internal bit (probes included) emitted by some reachable reaction, and every task
    activation (task, where) running in some reachable state (or as much as shows all of `want`)."""
    internal = (1 << len(a.program.internals)) - 1
    pin, pint = K.pre_masks(main, safe)
    prev: dict[int, tuple[int, int]] = {0: (0, 0)}  # what `pre(S)` sees in each state
    terms: dict[int, K.Term] = {0: main}
    fired = 0
    running: set[tuple[int, Loc]] = set()
    queue = deque([0])
    while queue:
        if fired & want.probes == want.probes and running >= want.running:
            break  # every site is executed: a mission without dead code stops early
        s = queue.popleft()
        for inputs, (n, actions) in a.table[s].items():
            emitted = (actions >> a.emit_base) & internal
            r = K.Instant(inputs, emitted, a.program.end_masks)
            r.prev_in, r.prev_int = prev[s]
            phase, nxt = _react(terms[s], a.phase[s], safe, r)
            if phase != a.phase[n] or r.emitted & internal != emitted:
                msg = f"the replay of state {s} under inputs {inputs} disagrees with the automaton"
                raise CoverageError(msg)
            fired |= r.emitted
            if n not in terms and nxt is not None:
                terms[n] = nxt
                prev[n] = (inputs & pin, emitted & pint)
                queue.append(n)
                _running(nxt, running)
    return fired, running


def _running(t: K.Term | None, out: set[tuple[int, Loc]]) -> None:
    """The task activations a paused term keeps running (as `K.active_tasks`, with their places)."""
    if isinstance(t, K.Running | K.Started):
        out.add((t.task, t.loc))
    elif isinstance(t, K.Seq):
        _running(t.first, out)
    elif isinstance(t, K.Par):
        for b in t.branches:
            _running(b, out)
    elif isinstance(t, K.Abort | K.Trap | K.Handle | K.Suspend):
        _running(t.body, out)


def _react(term: K.Term, phase: int, safe: K.Term, r: K.Instant) -> tuple[int, K.Term | None]:
    """One instant of the mission as the compiler runs it: (next phase, next term)."""
    if phase == MAIN:
        code, res = K.step(term, r)
        if code == K.PAUSED:
            return MAIN, K.settle(res)
        if code == K.DONE:
            return END, None
        term = safe  # `safe`: the safe procedure starts in this instant
    code, res = K.step(term, r)
    return (SAFE, K.settle(res)) if code == K.PAUSED else (END, None)


def _probed(t: K.Term, probes: dict[int, int]) -> K.Term:
    """`t` with `emit probe` before every sub-term that starts a site."""
    bits = probes.get(id(t), 0)
    new = _map_children(t, probes)
    return K.seq((K.Emit(bits), new)) if bits else new


def _map_children(t: K.Term, probes: dict[int, int]) -> K.Term:
    if isinstance(t, K.Seq):
        return K.seq(tuple(_probed(item, probes) for item in t.parts()))
    if isinstance(t, K.Par):
        return K.Par(tuple(None if b is None else _probed(b, probes) for b in t.branches))
    if isinstance(t, K.Loop):
        return K.Loop(_probed(t.body, probes), t.loc)
    if isinstance(t, K.Abort):
        return K.Abort(_probed(t.body, probes), t.cond, t.weak, t.armed)
    if isinstance(t, K.Suspend):
        return K.Suspend(_probed(t.body, probes), t.cond, t.armed)
    if isinstance(t, K.Trap):
        return K.Trap(t.code, _probed(t.body, probes))
    if isinstance(t, K.Present):
        return K.Present(t.cond, _probed(t.then, probes), _probed(t.orelse, probes))
    if isinstance(t, K.Handle):
        handlers = tuple(_probed(h, probes) for h in t.handlers)
        return K.Handle(_probed(t.body, probes), t.conds, handlers)
    return t
