"""A `par` of independent branches compiled apart: a network of explicit automata, not their product.

Ten branches of five tasks make ~6^10 product states: no explicit table holds them. When a `par`
in the main procedure has *independent* branches (`find_split`: no two branches share a task's
resource, an input or an internal signal, and no signal crosses the par's boundary) and the
product of the branches' own automata would be large, the mission compiles to

- one automaton per branch (`compile_branch`), whose transitions also give the branch's
  completion code (Esterel's: paused, done, or the exit of an enclosing trap; the `par`'s code is
  the max of its branches');
- the automaton of the *context* (the main procedure with the par replaced by a `Hole`, the safe
  procedure), for which the par's code in an instant is one more input; the branch tasks' events
  the context tests (its `on fatal`) enter as classes (`hole_classes`: events the context cannot
  tell apart), and its actions say whether the instant steps the par and whether it kills it.

An instant a component cannot react to (not causal, a loop restarting within the instant) is left
out of its table rather than refused: a component is explored on its own, beyond what the whole
mission can reach; the verifier's products (explicit, exact for the context and the branch they
hold) refuse the mission where it can get there, with the path.

`NetworkRunner` steps them together: one lookup in the context, and one per branch an input of
the instant concerns (or that moves on its own); the others stay paused at no cost. The verifier
(`checks/network_verify.py`) checks products of the context with one branch at a time.

Not split: a par inside the safe procedure, whose branches interact, or that a loop can end and
start again within one instant (`loop par(...) end`: the context would step it twice); those
compile as one product as before. A par in a loop that pauses in between (`loop await Go;
par(...) end`), or that a preemption kills and the loop restarts at once (`loop do par(...) until
S end`: killed, then started afresh) is split.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Hashable, Iterator
from dataclasses import dataclass
from types import MappingProxyType
from typing import Generic, TypeVar

from orccadd.automaton.compiler.automaton import END, MAIN, Automaton
from orccadd.automaton.compiler.classes import event_classes
from orccadd.automaton.compiler.constructive import Env, analyse
from orccadd.automaton.compiler.explicit import (
    DEFAULT_MAX_STATES,
    ActionLayout,
    Progress,
    Reactor,
    Top,
    _CausalityError,
    automaton_of,
    bits_of,
    compile_program,
    describe_state,
    input_combinations,
    instant_actions,
    possible_inputs,
    resolve,
)
from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.ast import Loc
from orccadd.automaton.language.program import Program, Site
from orccadd.errors import MissionError

# A par is compiled apart when its branches' state counts multiplied exceed this (below, the
# product is small and one explicit automaton is simpler to check, draw and export).
NETWORK_THRESHOLD = 1000
S = TypeVar("S", bound=Hashable)


@dataclass(frozen=True)
class Split:
    """Where the main procedure splits: the par, its branches and what each may react to."""

    par: K.Par
    loc: Loc
    branches: tuple[K.Term, ...]
    inputs: tuple[int, ...]  # per branch: every input bit it may react to (its tasks' events, its tests)
    tasks: tuple[frozenset[int], ...]  # per branch: the tasks it runs
    in_loop: bool  # a loop may start it again in the instant a preemption kills it


def find_split(p: Program) -> Split | None:
    """The `par` of the main procedure whose branches are independent (see the module
    docstring), with the most branches (then the most statements; then the outermost); None if
    there is none."""
    if any(K.pre_masks(p.main, p.safe)):
        return None  # `pre(S)` adds memory to the states: not split (yet)
    best: tuple[int, int] = (0, 0)
    found = None
    for par, in_loop in _pars(p.main):
        split = _independent(p, par, in_loop)
        if split is not None:
            size = (len(split.branches), sum(1 for _ in _walk(par)))
            if size > best:
                best, found = size, split
    return found


def _pars(t: K.Term | None) -> Iterator[tuple[K.Par, bool]]:
    """Every `par`, and whether a loop encloses it."""
    stack: list[tuple[K.Term | None, bool]] = [(t, False)]
    while stack:
        x, in_loop = stack.pop()
        if isinstance(x, K.Par):
            yield x, in_loop
        inner = in_loop or isinstance(x, K.Loop)
        stack.extend((c, inner) for c in K.children(x))


def _walk(t: K.Term | None) -> Iterator[K.Term]:
    stack = [t]
    while stack:
        t = stack.pop()
        if t is not None:
            yield t
            stack.extend(K.children(t))


def _emits(t: K.Term | None) -> int:
    return sum({x.bit for x in _walk(t) if isinstance(x, K.Emit)})


def _independent(p: Program, par: K.Par, in_loop: bool) -> Split | None:
    branches = [b for b in par.branches if b is not None]
    if len(branches) < 2:
        return None
    context = substitute(p.main, par, K.Hole(_loc_of(par), False))[0]
    around = 0  # events of the tasks the main procedure runs around the par (before, after, beside)
    for x in _walk(context):
        if isinstance(x, K.Run):
            around |= p.event_masks[x.task]
    tasks, ins, tested, emitted = [], [], [], []
    for b in branches:
        run = frozenset(x.task for x in _walk(b) if isinstance(x, K.Run))
        b_ins, b_tested = K.mentions(b, p.end_masks)
        own = 0
        for t in run:
            own |= p.event_masks[t]
        if b_ins & around & ~own:
            return None  # it reacts to a task that runs around the par
        b_ins |= own
        tasks.append(run)
        ins.append(b_ins)
        tested.append(b_tested)
        emitted.append(_emits(b))
    ctx_tested = K.mentions(context, p.end_masks)[1] | K.mentions(p.safe, p.end_masks)[1]
    ctx_emitted = _emits(context) | _emits(p.safe)
    for i in range(len(branches)):
        others_tested = ctx_tested | sum(tested[j] for j in range(len(branches)) if j != i)
        others_emitted = ctx_emitted | sum(emitted[j] for j in range(len(branches)) if j != i)
        if emitted[i] & others_tested or tested[i] & others_emitted:
            return None
        for j in range(i + 1, len(branches)):
            if ins[i] & ins[j]:
                return None
            if any(p.tasks[a].claims_overlap(p.tasks[b]) for a in tasks[i] for b in tasks[j]):
                return None
    return Split(par, _loc_of(par), tuple(branches), tuple(ins), tuple(tasks), in_loop)


def _loc_of(t: K.Term) -> Loc:
    """Where a term was written: its first statement that carries a location."""
    for x in _walk(t):
        loc = getattr(x, "loc", None)
        if isinstance(loc, Loc):
            return loc
    return Loc("<mission>", 1, 1)


def substitute(t: K.Term, target: K.Term, new: K.Term) -> tuple[K.Term, dict[int, K.Term]]:
    """`t` with the sub-term `target` (found by identity) replaced by `new`, and the rebuilt
    ancestors (id of the old term → the new one); every other sub-term is kept as it is."""
    rebuilt: dict[int, K.Term] = {}

    def go(x: K.Term | None) -> K.Term | None:
        if x is target:
            return new
        kids = K.children(x)
        if not kids:
            return x
        new_kids = [go(c) for c in kids]
        if all(a is b for a, b in zip(kids, new_kids, strict=True)):
            return x
        assert x is not None
        y = _with_children(x, new_kids)
        rebuilt[id(x)] = y
        return y

    out = go(t)
    assert out is not None
    return out, rebuilt


def _with_children(t: K.Term, kids: list[K.Term | None]) -> K.Term:
    if isinstance(t, K.Seq):
        return K.Seq(tuple(k for k in kids if k is not None))
    if isinstance(t, K.Par):
        return K.Par(tuple(kids))
    if isinstance(t, K.Present):
        assert kids[0] is not None and kids[1] is not None
        return K.Present(t.cond, kids[0], kids[1])
    if isinstance(t, K.Handle):
        assert kids[0] is not None
        return K.Handle(kids[0], t.conds, tuple(k for k in kids[1:] if k is not None))
    assert kids[0] is not None and isinstance(t, K.Abort | K.Loop | K.Trap | K.Suspend)
    return dataclasses.replace(t, body=kids[0])


def remap_sites(sites: tuple[Site, ...], rebuilt: dict[int, K.Term]) -> tuple[Site, ...]:
    """The dead-code sites of a program whose ancestors of one sub-term were rebuilt."""
    return tuple(
        dataclasses.replace(s, term=rebuilt[id(s.term)]) if id(s.term) in rebuilt else s for s in sites
    )


# the network ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Network:
    """A mission compiled as a network (see the module docstring). Never mutated."""

    program: Program
    split: Split
    context: Automaton  # keys: inputs | code index above them; actions: + the four flags below
    branches: tuple[Automaton, ...]  # actions: + code index << code_shift; state `ended` = last
    codes: tuple[int, ...]  # the par's possible completion codes (PAUSED, DONE, exits), indexed
    hole_classes: tuple[tuple[int, int], ...]  # (event bits of branch tasks, their representative)
    code_shift: int
    step_bit: int  # the instant steps the par (takes its branches' reactions)
    kill_bit: int  # and kills it afterwards (or without a step)
    kill_first_bit: int  # kills it, then starts it afresh (a loop around a preemption)
    fresh_bit: int  # the step starts the par afresh (its code is the branches' first instant's)
    hole_alive: tuple[bool, ...]  # per context state: the par runs (started in an earlier instant)
    hole_present: tuple[bool, ...]  # per context state: the par runs or may start

    @property
    def n_states(self) -> int:
        return self.context.n_states + sum(b.n_states for b in self.branches)

    @property
    def n_transitions(self) -> int:
        return self.context.n_transitions + sum(b.n_transitions for b in self.branches)

    @property
    def product_states(self) -> int:
        """How many states the branches' product would have (their counts multiplied)."""
        return math.prod(b.n_states for b in self.branches)

    def describe(self) -> str:
        sizes = ", ".join(str(b.n_states) for b in self.branches)
        return (
            f"a network: the context ({self.context.n_states} states) and the {len(self.branches)} "
            f"branches of the par at line {self.split.loc.line} ({sizes} states; their product "
            f"would have {self.product_states:.3g})"
        )


def compile_mission(
    p: Program,
    max_states: int = DEFAULT_MAX_STATES,
    threshold: int = NETWORK_THRESHOLD,
    progress: Progress | None = None,
) -> Automaton | Network:
    """A network when the main procedure splits and the branches' product would be large
    (> `threshold` states), else the one explicit automaton (`compile_program`)."""
    split = find_split(p)
    if split is not None:
        layout = ActionLayout(p)
        code_shift = (layout.safe_done_bit << 5).bit_length()  # above the context's four flags
        branches = [compile_branch(p, b, code_shift, max_states, split.in_loop) for b in split.branches]
        if math.prod(len(b.table) for b, _ in branches) > threshold:
            try:
                return _network(p, split, branches, layout, code_shift, max_states)
            except K.HoleTwiceError:
                pass  # a loop ends the par and starts it again in one instant: one automaton
    return compile_program(p, max_states, progress)


def compile_branch(
    p: Program, branch: K.Term, code_shift: int, max_states: int, restarts: bool = False
) -> tuple[Automaton, frozenset[int]]:
    """A branch on its own: state 0 is the branch about to start, the last state `ended`; each
    transition's actions carry its completion code (`code << code_shift`, the raw code here:
    `_network` renumbers them). Also the codes its transitions end with. `restarts`: a loop may
    start it again in the instant it is killed (its first instant may see its tasks' events)."""
    layout = ActionLayout(p)
    classes = event_classes(p)
    reps = [sum(c.rep for c in task) for task in classes]
    terms = _States[K.Term](p, "a branch's automaton", max_states)
    terms.add(branch)
    relevant, table, active = [], [], []
    codes: set[int] = set()
    ended = -1  # patched below: the index of the `ended` state
    # started afresh by a loop in the instant it was killed, the branch's first instant may see
    # events of its tasks' previous activations (raised in that instant, before the kill): those
    # its conditions test (no task of its own runs yet, so no task's end is tested then)
    own_events = 0
    for t in {x.task for x in _walk(branch) if isinstance(x, K.Run)}:
        own_events |= p.event_masks[t]
    own_events &= _tested_inputs(branch) if restarts else 0
    own_tasks = [t for t in range(len(p.tasks)) if p.event_masks[t] & own_events]
    while terms.queue:
        s = terms.queue.popleft()
        term = terms.items[s]
        act = tuple(sorted(K.active_tasks(term, [])))
        ins, internal = K.mentions(term, p.end_masks)
        rel = ins & (possible_inputs(p, act) | (own_events if s == 0 else 0))
        row: dict[int, tuple[int, int]] = {}
        raising = tuple(sorted({*act, *own_tasks})) if s == 0 else act
        for inputs in _combinations(p, raising, rel, reps):

            def run(r: K.Instant, term: K.Term = term) -> tuple[int, K.Term | None, int]:
                code, res = K.step(term, r)
                return code, (K.settle(res) if code == K.PAUSED else None), instant_actions(layout, r)

            def outcomes(
                present: int, absent: int, term: K.Term = term, inputs: int = inputs
            ) -> tuple[int, int]:
                o = analyse(term, Env(inputs, present, absent, end_masks=p.end_masks))
                return o.must, o.can

            try:
                code, nxt, actions = resolve(p, inputs, internal, run, outcomes)
            except (K.InstantaneousLoopError, _CausalityError):
                continue  # no reaction: the verifier's products refuse it if the mission can get here
            if nxt is None:
                codes.add(code)
                row[inputs] = (ended, actions | code << code_shift)
                continue
            row[inputs] = (terms.add(nxt), actions | K.PAUSED << code_shift)
        relevant.append(rel)
        table.append(row)
        active.append(act)
    n = len(terms.items)
    table = [{k: (n if j == ended else j, a) for k, (j, a) in row.items()} for row in table]
    phase = [*(MAIN for _ in terms.items), END]
    where = [*(describe_state(p, Top(MAIN, t)) for t in terms.items), "ended"]
    a = automaton_of(p, layout, classes, [*relevant, 0], [*table, {0: (n, 0)}], [*active, ()], phase, where)
    return a, frozenset(codes)


def _tested_inputs(t: K.Term) -> int:
    """The input bits the conditions of a term test."""
    out = 0
    for x in _walk(t):
        for c in K.conds(x):
            out |= K.cond_masks(c)[0]
    return out


def _combinations(p: Program, act: tuple[int, ...], rel: int, reps: list[int]) -> list[int]:
    try:
        return input_combinations(p, act, rel, reps)
    except OverflowError as e:
        msg = f"a state of a branch reacts to {e.args[0]} input combinations: too many tasks active at once"
        raise MissionError(p.file, 1, 1, msg, p.text) from None


class _States(Generic[S]):
    """Explored states, numbered in the order found; each new one queued for exploration."""

    def __init__(self, p: Program, what: str, max_states: int) -> None:
        self.p, self.what, self.max_states = p, what, max_states
        self.index: dict[S, int] = {}
        self.items: list[S] = []
        self.queue: deque[int] = deque()

    def add(self, x: S) -> int:
        i = self.index.get(x)
        if i is None:
            if len(self.items) >= self.max_states:
                msg = f"{self.what} exceeds {self.max_states} states"
                raise MissionError(self.p.file, 1, 1, msg, self.p.text)
            i = self.index[x] = len(self.items)
            self.items.append(x)
            self.queue.append(i)
        return i


class _ContextReactor(Reactor):
    """The context's instant, given the par's completion code; marks stepping and killing it."""

    def __init__(self, p: Program, layout: ActionLayout, flags: tuple[int, int, int, int]) -> None:
        super().__init__(p, layout)
        self.code = K.PAUSED
        self.flags = flags  # step, kill, kill first, fresh

    def _hole_code(self) -> int:
        return self.code

    def _run(self, top: Top, r: K.Instant) -> tuple[Top, int]:
        r.hole_code = self.code
        nxt, actions = super()._run(top, r)
        step, kill, kill_first, fresh = self.flags
        for on, bit in ((r.hole_stepped, step), (r.hole_killed, kill), (r.hole_killed_first, kill_first)):
            if on:
                actions |= bit
        if r.hole_stepped and r.hole_fresh:
            actions |= fresh
        return nxt, actions


def _has_hole(t: K.Term | None) -> bool:
    return any(isinstance(x, K.Hole) for x in _walk(t))


def _hole_alive(t: K.Term | None) -> bool:
    return any(isinstance(x, K.Hole) and x.alive for x in _walk(t))


def hole_classes(p: Program, context: K.Term, split: Split) -> list[tuple[int, int]]:
    """The branch tasks' events the context tests, grouped by the masks that hold them (the
    context reacts to a group's presence, not to which of its events came): (bits, rep)."""
    hole_tasks = set().union(*split.tasks)
    masks: set[int] = set()
    for root in (context, p.safe):
        for x in _walk(root):
            for c in K.conds(x):
                masks.add(K.cond_masks(c)[0])
    masks |= {m for t, m in enumerate(p.end_masks) if t not in hole_tasks}
    hole_events = 0
    for task in hole_tasks:
        hole_events |= p.event_masks[task]
    groups: dict[tuple[int, ...], int] = {}
    for bit in bits_of(hole_events):
        where = tuple(sorted(m for m in masks if m & bit))
        if where:
            groups[where] = groups.get(where, 0) | bit
    return [(bits, bits & -bits) for bits in groups.values()]


def _network(
    p: Program,
    split: Split,
    branches: list[tuple[Automaton, frozenset[int]]],
    layout: ActionLayout,
    code_shift: int,
    max_states: int,
) -> Network:
    raw_codes = set().union(*(c for _, c in branches))
    codes = (K.DONE, K.PAUSED, *sorted(c for c in raw_codes if c > K.PAUSED))
    number = {c: i for i, c in enumerate(codes)}
    renumbered = tuple(_renumber(a, code_shift, number) for a, _ in branches)
    context_term, rebuilt = substitute(p.main, split.par, K.Hole(split.loc, False))
    q = dataclasses.replace(p, main=context_term, sites=remap_sites(p.sites, rebuilt))
    flags = (
        layout.safe_done_bit << 1,
        layout.safe_done_bit << 2,
        layout.safe_done_bit << 3,
        layout.safe_done_bit << 4,
    )
    classes = hole_classes(p, context_term, split)
    context, alive, present = _compile_context(q, layout, classes, codes, flags, max_states)
    line = split.loc.line
    names = (f"step the par at line {line}", "kill it", "kill it, then start it again", "afresh")
    context = dataclasses.replace(context, action_names=(*layout.names, *names))
    return Network(p, split, context, renumbered, codes, tuple(classes), code_shift, *flags, alive, present)


def _renumber(a: Automaton, shift: int, number: dict[int, int]) -> Automaton:
    low = (1 << shift) - 1
    rows = tuple(
        MappingProxyType({k: (j, (act & low) | number[act >> shift] << shift) for k, (j, act) in row.items()})
        for row in a.table
    )
    return dataclasses.replace(a, table=rows)


def _compile_context(
    q: Program,
    layout: ActionLayout,
    classes: list[tuple[int, int]],
    codes: tuple[int, ...],
    flags: tuple[int, int, int, int],
    max_states: int,
) -> tuple[Automaton, tuple[bool, ...], tuple[bool, ...]]:
    """The context's automaton: inputs are its own, the branch-event classes' representatives and,
    where the par is present (started or about to), the par's code index above the inputs."""
    code_base = len(q.inputs)
    code_mask = ((1 << max(1, (len(codes) - 1).bit_length())) - 1) << code_base
    ev_classes = event_classes(q)
    reps = [sum(c.rep for c in task) for task in ev_classes]
    hole_reps = [rep for _, rep in classes]
    hole_events = sum(bits for bits, _ in classes)
    reactor = _ContextReactor(q, layout, flags)
    states = _States[Top](q, "the context's automaton", max_states)
    states.add(Top(MAIN, q.main, first=True))
    relevant, table, active = [], [], []
    while states.queue:
        s = states.queue.popleft()
        top = states.items[s]
        act = tuple(sorted(K.active_tasks(top.term, [])))
        possible = possible_inputs(q, act, first=top.first)
        ins, internal = reactor.mentions(top)
        hole = top.phase == MAIN and _has_hole(top.term)
        # where the par is, its tasks' events count by class (`hole_classes`); elsewhere (the safe
        # procedure running a task of a branch again) they are the context's own inputs
        rel = ins & possible & ~hole_events if hole else ins & possible
        plain = _combinations(q, act, rel, reps)
        extra = [0]
        if hole:
            rel |= sum(hole_reps) | code_mask
            for rep in hole_reps:
                extra = [x | y for x in extra for y in (0, rep)]
            extra = [x | i << code_base for x in extra for i in range(len(codes))]
        row: dict[int, tuple[int, int]] = {}
        for inputs in (x | y for x in plain for y in extra):
            reactor.code = codes[inputs >> code_base] if hole else K.PAUSED
            real = inputs & ((1 << code_base) - 1)
            try:
                nxt, actions = reactor.react(top, real, internal)
            except (K.InstantaneousLoopError, _CausalityError):
                continue  # as in a branch (the par's codes here include some it may never give)
            row[inputs] = (states.add(nxt), actions)
        relevant.append(rel)
        table.append(row)
        active.append(act)
    phase = [t.phase for t in states.items]
    where = [describe_state(q, t) for t in states.items]
    automaton = automaton_of(q, layout, ev_classes, relevant, table, active, phase, where)
    alive = tuple(t.phase == MAIN and _hole_alive(t.term) for t in states.items)
    present = tuple(t.phase == MAIN and _has_hole(t.term) for t in states.items)
    return automaton, alive, present
