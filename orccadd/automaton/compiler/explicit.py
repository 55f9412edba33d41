"""Kernel terms → one explicit automaton, by exploring every reachable state under every input
combination the environment can produce (synchronous semantics, one reaction per instant).

Environment model, shared with the verifier: operator inputs may come in any combination; a
Robot-Task raises events only while active, at most one per instant (the runtime keeps the most
severe of one tick's events: T3 > T2 > post > pre > sync). Events the program cannot tell apart
are explored once, through their class's representative (`compiler/classes.py`: e.g. a task's built-in
type 3 exceptions under one `on fatal`).
"""

from __future__ import annotations

import itertools
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType
from typing import TypeVar

from orccadd.automaton.compiler.automaton import END, MAIN, SAFE, Automaton
from orccadd.automaton.compiler.causality import dependencies, find_cycle
from orccadd.automaton.compiler.classes import EventClass, event_classes, event_reps
from orccadd.automaton.compiler.constructive import Env, analyse, establish
from orccadd.automaton.language import ast as A
from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.program import Program
from orccadd.errors import MissionError

DEFAULT_MAX_STATES = 200_000
MAX_INPUT_COMBINATIONS = 1 << 16


@dataclass(frozen=True, slots=True)
class Top:
    """A state of the mission: which part runs (main, safe procedure, ended), its residual term,
    what the previous instant had of the signals some `pre(S)` tests, and whether it is the
    mission's first instant (state 0 only: a resource's fault cannot come then, and it can in a
    later instant whose residual term is the initial one, as after `await immediate S`)."""

    phase: int
    term: K.Term
    prev_in: int = 0
    prev_int: int = 0
    first: bool = False


class ReactionError(MissionError):
    """The program has no single reaction in some reachable instant (non-causal, instantaneous loop)."""

    def __init__(self, p: Program, line: int, col: int, message: str, path: list[int]) -> None:
        trace = "; ".join(f"instant {i + 1}: {p.describe_inputs(m)}" for i, m in enumerate(path))
        super().__init__(
            p.file, line, col, f"{message}\n  reached by: {trace or 'the first instant'}", p.text
        )
        self.path = path


def bits_of(mask: int) -> list[int]:
    out = []
    while mask:
        low = mask & -mask
        out.append(low)
        mask ^= low
    return out


class ActionLayout:
    def __init__(self, p: Program) -> None:
        n, e = len(p.tasks), len(p.internals)
        self.stop_base, self.start_base, self.emit_base = 0, n, 2 * n
        self.success_bit = 1 << (2 * n + e)
        self.safe_bit = self.success_bit << 1
        self.failed_bit = self.success_bit << 2
        self.safe_done_bit = self.success_bit << 3
        self.names = (
            *(f"stop {t.name}" for t in p.tasks),
            *(f"start {t.name}" for t in p.tasks),
            *(f"emit {s}" for s in p.internals),
            "success",
            "safe",
            "failed",
            "safe done",
        )


def possible_inputs(p: Program, active: tuple[int, ...], first: bool = False) -> int:
    """The inputs the environment can give in a state: operator inputs, events of its active tasks,
    the faults of the resources none of them runs on, except in the mission's `first` instant (the
    daemon takes it at `start`, every resource ready, with no event)."""
    possible = p.operator_mask | (0 if first else p.faults_possible(active))
    for t in active:
        possible |= p.event_masks[t]
    return possible


def input_combinations(p: Program, active: tuple[int, ...], relevant: int, reps: list[int]) -> list[int]:
    """Every input set the environment can present in a state (see the module docstring), one
    event per class of each active task (`reps[t]`: the bits of task t's class representatives)."""
    choices: list[list[int]] = [[0, *bits_of(reps[t] & relevant)] for t in sorted(set(active))]
    ops = bits_of(relevant & p.operator_mask)
    choices.extend([0, b] for b in ops)
    faults = bits_of(relevant & p.fault_mask)
    if faults:  # one resource's fault at most per instant (the daemon gives each its own instant)
        choices.append([0, *faults])
    count = 1
    for c in choices:
        count *= len(c)
    if count > MAX_INPUT_COMBINATIONS:
        raise OverflowError(count, len(set(active)), len(ops))
    return [sum(combo) for combo in itertools.product(*choices)]


R = TypeVar("R")


Outcomes = Callable[[int, int], tuple[int, int]]  # (present, absent) → (must emit, can emit)


def resolve(
    p: Program, inputs: int, internal: int, run: Callable[[K.Instant], R], outcomes: Outcomes | None = None
) -> R:
    """The one consistent outcome of an instant (`run` evaluates it under guessed statuses of the
    internal signals it may test), which constructive semantics must establish (`outcomes`: the
    instant in three-valued logic, `constructive.analyse`): every signal the instant tests present
    because it must be emitted or absent because it cannot be. Raises K.InstantaneousLoopError or
    _CausalityError."""
    solutions: dict[tuple[int, int], tuple[R, int]] = {}
    candidates = bits_of(internal)
    for n in range(len(candidates) + 1):
        for subset in itertools.combinations(candidates, n):
            assumed = sum(subset)
            r = K.Instant(inputs, assumed, p.end_masks)
            out = run(r)
            if (r.emitted & r.reads) == (assumed & r.reads):
                solutions[(assumed & r.reads, r.emitted)] = (out, r.reads)
    if len(solutions) != 1:
        raise _CausalityError(internal, len(solutions))
    ((assumed, _), (out, reads)), *_ = solutions.items()
    if reads and outcomes is not None:
        present, absent = establish(internal, outcomes)
        unknown = reads & ~(present | absent)
        if unknown or present & reads != assumed:
            raise _CausalityError(unknown or reads, 1, constructive=False)
    return out


def instant_actions(lay: ActionLayout, r: K.Instant) -> int:
    """The action bits of an evaluated instant: emits, tasks started (not cancelled), stopped."""
    actions = r.emitted << lay.emit_base
    started = list(r.started)
    for t in r.cancelled:
        started.remove(t)
    for t in started:
        actions |= 1 << (lay.start_base + t)
    for t in r.stopped:
        actions |= 1 << (lay.stop_base + t)
    return actions


class Reactor:
    """One instant of a whole mission (main, then the safe procedure), causality resolved."""

    def __init__(self, p: Program, layout: ActionLayout) -> None:
        self.p = p
        self.layout = layout
        # the safe procedure can start within any instant of the main one: its tests count there too
        self.safe_mentions = K.mentions(p.safe, p.end_masks)
        self.pin, self.pint = K.pre_masks(p.main, p.safe)

    def mentions(self, top: Top) -> tuple[int, int]:
        """(inputs, internal signals) an instant of this state may test; computed once per state."""
        if top.phase == END:
            return 0, 0
        ins, internal = K.mentions(top.term, self.p.end_masks)
        if top.phase == MAIN:
            ins |= self.safe_mentions[0]
            internal |= self.safe_mentions[1]
        return ins, internal

    def react(self, top: Top, inputs: int, internal: int) -> tuple[Top, int]:
        """(next state, action bits). Raises K.InstantaneousLoopError or _CausalityError."""
        return resolve(self.p, inputs, internal, lambda r: self._run(top, r), self._outcomes(top, inputs))

    def _hole_code(self) -> int:
        """The par's code in this instant (a network's context: `_ContextReactor`)."""
        return K.PAUSED

    def _outcomes(self, top: Top, inputs: int) -> Outcomes:
        """The instant in three-valued logic: main, then the safe procedure if main can exit to it."""
        p, hole = self.p, self._hole_code()

        def outcomes(present: int, absent: int) -> tuple[int, int]:
            env = Env(inputs, present, absent, top.prev_in, top.prev_int, p.end_masks, hole)
            o = analyse(top.term, env)
            must, can = o.must, o.can
            if top.phase == MAIN and K.SAFE_CODE in o.can_codes:
                s = analyse(p.safe, env)
                can |= s.can
                must |= s.must if o.must_code == K.SAFE_CODE else 0
            return must, can

        return outcomes

    def _run(self, top: Top, r: K.Instant) -> tuple[Top, int]:
        lay = self.layout
        flags = 0
        if top.phase == END:
            return top, 0
        r.prev_in, r.prev_int = top.prev_in, top.prev_int
        if top.phase == MAIN:
            code, res = K.step(top.term, r)
            if code == K.PAUSED:
                nxt = Top(MAIN, K.settle(res))
            elif code == K.DONE:
                nxt, flags = Top(END, K.NOTHING), lay.success_bit
            else:  # SAFE_CODE: the only exit that can leave the main procedure
                flags = lay.safe_bit
                nxt, more = self._safe(self.p.safe, r)
                flags |= more
        else:
            nxt, flags = self._safe(top.term, r)
        if (self.pin or self.pint) and nxt.phase != END:
            nxt = Top(nxt.phase, nxt.term, r.inputs & self.pin, r.emitted & self.pint)
        return nxt, flags | instant_actions(lay, r)

    def _safe(self, term: K.Term, r: K.Instant) -> tuple[Top, int]:
        code, res = K.step(term, r)
        if code == K.PAUSED:
            return Top(SAFE, K.settle(res)), 0
        if code == K.FAILED_CODE:
            return Top(END, K.NOTHING), self.layout.failed_bit
        return Top(END, K.NOTHING), self.layout.safe_done_bit


class _CausalityError(Exception):
    def __init__(self, internal: int, solutions: int, constructive: bool = True) -> None:
        super().__init__(internal, solutions)
        self.internal = internal  # the signals concerned
        self.solutions = solutions  # how many consistent statuses the instant has
        self.constructive = constructive  # False: its one status cannot be established


Progress = Callable[[int, int, float], None]  # (states, transitions, seconds so far)
PROGRESS_EVERY_S = 0.5


def compile_program(
    p: Program, max_states: int = DEFAULT_MAX_STATES, progress: Progress | None = None
) -> Automaton:
    """Explore every reachable state (breadth first, so counterexamples are shortest).
    `progress` is told the count every `PROGRESS_EVERY_S` (a long compilation on a terminal)."""
    layout = ActionLayout(p)
    classes = event_classes(p)
    reps = [sum(c.rep for c in task) for task in classes]
    t0 = last = time.monotonic()
    n_transitions = 0
    reactor = Reactor(p, layout)
    index: dict[Top, int] = {}
    states: list[Top] = []
    parent: list[tuple[int, int]] = []  # (previous state, inputs) for counterexample paths
    relevant: list[int] = []
    table: list[dict[int, tuple[int, int]]] = []
    active: list[tuple[int, ...]] = []

    def add(top: Top, via: tuple[int, int]) -> int:
        i = index.get(top)
        if i is None:
            if len(states) >= max_states:
                raise MissionError(
                    p.file, 1, 1,
                    f"the mission's automaton exceeds {max_states} states (state explosion: look for many "
                    "parallel branches waiting independently); split the mission or raise the limit",
                    p.text,
                )  # fmt: skip
            i = len(states)
            index[top] = i
            states.append(top)
            parent.append(via)
        return i

    add(Top(MAIN, p.main, first=True), (-1, 0))
    queue = deque([0])
    while queue:
        s = queue.popleft()
        top = states[s]
        act = tuple(sorted(K.active_tasks(top.term, [])))
        ins, internal = reactor.mentions(top)
        rel = ins & possible_inputs(p, act, first=top.first)
        try:
            combos = input_combinations(p, act, rel, reps)
        except OverflowError as e:
            msg = (f"a state reacts to {e.args[0]} input combinations (limit {MAX_INPUT_COMBINATIONS}): "
                   f"too many Robot-Tasks active at once ({e.args[1]}, with their events, and "
                   f"{e.args[2]} operator inputs)")  # fmt: skip
            raise MissionError(p.file, 1, 1, msg, p.text) from None
        row: dict[int, tuple[int, int]] = {}
        for inputs in combos:
            try:
                nxt, actions = reactor.react(top, inputs, internal)
            except K.InstantaneousLoopError as e:
                path = [*path_to(parent, s), inputs]
                msg = "this loop restarts within one instant: its body ended in the instant it started"
                raise ReactionError(p, e.loc.line, e.loc.col, msg, path) from None
            except _CausalityError as e:
                raise _causality_error(p, e, [*path_to(parent, s), inputs]) from None
            n_before = len(states)
            j = add(nxt, (s, inputs))
            if j == n_before:
                queue.append(j)
            row[inputs] = (j, actions)
        relevant.append(rel)
        table.append(row)
        active.append(act)
        n_transitions += len(row)
        if progress is not None and not s % 64 and time.monotonic() - last >= PROGRESS_EVERY_S:
            last = time.monotonic()
            progress(len(states), n_transitions, last - t0)
    return automaton_of(
        p,
        layout,
        classes,
        relevant,
        table,
        active,
        [t.phase for t in states],
        [describe_state(p, t) for t in states],
    )


def automaton_of(
    p: Program,
    layout: ActionLayout,
    classes: list[list[EventClass]],
    relevant: list[int],
    table: list[dict[int, tuple[int, int]]],
    active: list[tuple[int, ...]],
    phase: list[int],
    where: list[str],
) -> Automaton:
    """The immutable automaton of explored states (rows read-only: the checked table is what runs)."""
    return Automaton(
        program=p,
        relevant=tuple(relevant),
        table=tuple(MappingProxyType(row) for row in table),
        active=tuple(active),
        phase=tuple(phase),
        where=tuple(where),
        action_names=layout.names,
        stop_base=layout.stop_base,
        start_base=layout.start_base,
        emit_base=layout.emit_base,
        success_bit=layout.success_bit,
        safe_bit=layout.safe_bit,
        failed_bit=layout.failed_bit,
        safe_done_bit=layout.safe_done_bit,
        event_rep=event_reps(p, classes),
    )


def path_to(parent: list[tuple[int, int]], s: int) -> list[int]:
    """Input sequence from the initial state to state s."""
    out: list[int] = []
    while s > 0:
        s, inputs = parent[s]
        out.append(inputs)
    out.reverse()
    return out


def _causality_error(p: Program, e: _CausalityError, path: list[int]) -> MissionError:
    names = {p.internals[i] for i in range(len(p.internals)) if e.internal >> i & 1}
    deps = dependencies(p.ast, p.internals)
    cycle = find_cycle(deps, names)
    if cycle:
        chain = " -> ".join([cycle[0].tested, *(d.emitted for d in cycle)])
        why = "; ".join(
            f"`emit {d.emitted}` at line {d.emitted_at.line} depends on {d.tested} (tested at line "
            f"{d.tested_at.line})"
            for d in cycle
        )
        at = cycle[0].emitted_at
    else:
        chain, why = ", ".join(sorted(names)), "no emission chain found"
        at = next((d.emitted_at for d in deps if d.emitted in names), A.Loc(p.file, 1, 1))
    if not e.constructive:
        what = " and ".join(sorted(names))
        kind = (
            f"the status of {what} cannot be established: it is tested before anything must emit "
            "it, and something can (Esterel's constructive rule: a signal is present when it must "
            "be emitted, absent when it cannot be; a status that only justifies itself is refused)"
        )
        return ReactionError(p, at.line, at.col, f"not constructive, {chain}: {kind}; {why}", path)
    if e.solutions == 0:
        kind = "no consistent status (an emission depends on its own absence)"
    else:
        kind = "two consistent statuses (an emission justifies itself)"
    return ReactionError(p, at.line, at.col, f"not causal, cycle {chain}: {kind}; {why}", path)


def describe_state(p: Program, top: Top) -> str:
    if top.phase == END:
        return "ended"
    waits: list[str] = []
    _waits(p, top.term, waits)
    head = "safe procedure: " if top.phase == SAFE else ""
    return head + ("; ".join(waits) if waits else "running")


def _waits(p: Program, t: K.Term | None, out: list[str]) -> None:
    if isinstance(t, K.Running | K.Started):
        out.append(f"{p.tasks[t.task].name} running (line {t.loc.line})")
    elif isinstance(t, K.Await):
        out.append(f"await at line {t.loc.line}")
    elif isinstance(t, K.Hole):
        out.append(f"the par at line {t.loc.line} {'running' if t.alive else 'about to start'}")
    elif isinstance(t, K.Halt):
        out.append(f"halt at line {t.loc.line}")
    elif isinstance(t, K.Seq):
        _waits(p, t.first, out)
    elif isinstance(t, K.Par):
        for b in t.branches:
            _waits(p, b, out)
    elif isinstance(t, K.Abort | K.Trap | K.Handle | K.Suspend):
        _waits(p, t.body, out)
