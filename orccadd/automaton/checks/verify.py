"""Checks on the explicit automaton, each failure with a counterexample (a sequence of instants).

- determinism: every reachable instant has exactly one reaction (guaranteed by the compiler,
  which refuses non-causal programs and instantaneous loops);
- deadlock and non-progress: no state that nothing can move (no active task, no operator input
  that changes its reaction), no cycle the program runs through on its own without a task or an
  operator input; judged per state, so the inputs of the safe procedure (tested in every instant
  of the main one, in case it is entered) do not keep a stuck main procedure alive;
- safety: in every reachable state, a type 3 exception of any active Robot-Task, and a resource's
  fault (`R.fault`), enters the safe procedure in the same instant (or, inside the safe procedure,
  ends the mission as failed);
- liveness: with no exceptions (no T2, no T3), success stays reachable from every reachable state
  of the main procedure (the end of the safe procedure from every state of it);
- strong liveness: every run of each procedure ends (the main one in success or the safe
  procedure, the safe one done or failed), assuming every active task eventually ends and that
  operator inputs may never come; a counterexample is a lasso (a prefix, then a loop forever). An
  error only where the program spins or halts with nothing running and no way out, otherwise a
  note (waiting for the operator forever is legitimate);
- conflicts: no reachable state has two active tasks claiming the same resource or joints;
- the mission's own properties (observers): `never E`, `A -> eventually B`, `A and B alternate`
  (`-> eventually`, a liveness property, on the runs without a type 3 exception or a resource's
  fault, as liveness; the others on every run);
- dead code: every task activation, `emit` and branch is executed by some reachable reaction (a
  warning, an error in a strict report).

A failed check has a level: "error" refuses the mission, "warning" refuses it only when the
report is strict (`orccadctl check --strict`), "note" never does.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator, Set
from dataclasses import dataclass, field
from functools import partial

from orccadd.automaton.checks.coverage import CoverageError, executed_sites
from orccadd.automaton.compiler.automaton import END, MAIN, SAFE, Automaton
from orccadd.automaton.language import ast as A
from orccadd.automaton.language.program import Program, Site
from orccadd.types import TASK_TIMEOUT

ERROR, WARNING, NOTE = "error", "warning", "note"
_TAGS = {ERROR: "FAIL", WARNING: "warn", NOTE: "note"}


@dataclass(frozen=True)
class Step:
    inputs: int
    actions: int


@dataclass
class CheckResult:
    name: str
    ok: bool  # the property holds
    summary: str
    counterexample: list[Step] = field(default_factory=list)
    explanation: str = ""
    level: str = ERROR  # what a failure means: ERROR refuses the mission, WARNING if strict, NOTE never
    loop_start: int | None = None  # a lasso: counterexample[loop_start:] repeats forever
    automaton: Automaton | None = None  # the counterexample's, when not the report's (a network's product)


@dataclass
class Report:
    automaton: Automaton
    results: list[CheckResult]
    warnings: list[str]
    strict: bool = False  # warnings are errors (`orccadctl check --strict`)
    title: str = ""  # the first line, when not the automaton's size (a network)

    def level(self, r: CheckResult) -> str:
        return ERROR if self.strict and r.level == WARNING else r.level

    @property
    def ok(self) -> bool:
        """No check failed at the error level: what `load` and `check` accept."""
        return not any(not r.ok and self.level(r) == ERROR for r in self.results)

    def failed(self, name: str) -> bool:
        return any(r.name == name and not r.ok for r in self.results)

    def format(self) -> str:
        a = self.automaton
        head = self.title or f"{a.n_states} states, {a.n_transitions} transitions"
        lines = [f"mission {a.program.name}: {head}"]
        for r in self.results:
            lines.append(f"  {'ok  ' if r.ok else _TAGS[self.level(r)]} {r.name}: {r.summary}")
            if not r.ok and r.counterexample:
                lines.append("       counterexample:")
                trace = format_trace(r.automaton or a, r.counterexample, r.loop_start)
                lines.extend("         " + s for s in trace)
            if not r.ok and r.explanation:
                lines.extend(f"       {line}" for line in r.explanation.splitlines())
        lines.extend(f"  note: {w}" for w in self.warnings)
        return "\n".join(lines)


def format_trace(a: Automaton, trace: list[Step], loop_start: int | None = None) -> list[str]:
    """One line per instant; a lasso (`loop_start`) marks where its loop starts and ends."""
    p = a.program
    out = []
    for i, st in enumerate(trace, start=1):
        acts = ", ".join(a.describe_actions(st.actions)) or "-"
        mark = " (loop start)" if loop_start == i - 1 else ""
        out.append(f"instant {i}{mark}: inputs {p.describe_inputs(st.inputs)} -> {acts}")
    if loop_start is not None:
        out.append(f"... then from instant {loop_start + 1} again, forever")
    return out


class _Graph:
    """Reachability with shortest input paths from the initial state."""

    def __init__(self, a: Automaton) -> None:
        self.a = a
        self.parent: dict[int, tuple[int, int]] = {0: (-1, 0)}
        queue = deque([0])
        while queue:
            s = queue.popleft()
            for inputs, (n, _) in a.table[s].items():
                if n not in self.parent:
                    self.parent[n] = (s, inputs)
                    queue.append(n)

    def path(self, s: int) -> list[Step]:
        seq: list[int] = []
        while s > 0:
            s, inputs = self.parent[s]
            seq.append(inputs)
        seq.reverse()
        return self.replay(seq)

    def replay(self, inputs_seq: list[int]) -> list[Step]:
        s, out = 0, []
        for inputs in inputs_seq:
            s, actions = self.a.table[s][inputs]
            out.append(Step(inputs, actions))
        return out

    def edges(self) -> Iterator[tuple[int, int, int, int]]:
        for s in self.parent:
            for inputs, (n, actions) in self.a.table[s].items():
                yield s, inputs, n, actions


def verify(a: Automaton, *, one_task_per_resource: bool = False, dead_code: bool = True) -> Report:
    """Every check; `one_task_per_resource` adds the execution machine's own need (the daemon runs
    one Robot-Task at a time on each resource, one law per control loop:
    `orccadd.mission.check_mission`). `dead_code=False`
    leaves that check to the caller (a network's, over all its products)."""
    g = _Graph(a)
    results = [
        CheckResult(
            "determinism", True, f"every reachable instant has exactly one reaction ({len(g.parent)} states)"
        ),
        _check_progress(a, g),
        _check_safety(a, g),
        _check_liveness(a, g),
        _check_strong_liveness(a, g),
        _check_conflicts(a, g),
    ]
    if one_task_per_resource:
        results.append(_check_one_task(a, g))
    if a.program.remote_inputs:
        results.append(_check_peer_loss(a, g))
    results.extend(_check_property(a, g, prop) for prop in a.program.properties)
    if dead_code:
        results.append(_check_dead_code(a))
    return Report(a, results, _warnings(a, g))


def _t3_of_active(a: Automaton, s: int) -> int:
    m = 0
    for t in a.active[s]:
        m |= a.program.t3_masks[t]
    return m


def _check_safety(a: Automaton, g: _Graph) -> CheckResult:
    handled = a.safe_bit | a.failed_bit
    faults = a.program.fault_mask
    checked = 0
    for s, inputs, _, actions in g.edges():
        if inputs & (_t3_of_active(a, s) | faults):
            checked += 1
            if not actions & handled:
                names = [
                    n
                    for i, n in enumerate(a.program.inputs)
                    if inputs >> i & 1 and a.program.input_kind[i] in ("T3", "fault")
                ]
                return CheckResult(
                    "safety", False, f"type 3 exception {', '.join(names)} is not handled",
                    [*g.path(s), Step(inputs, actions)],
                    f"in the last instant the program was at: {a.where[s]}; it does not enter the safe "
                    "procedure (wrap the tasks in `handle ... on fatal do safe end`)",
                )  # fmt: skip
    return CheckResult(
        "safety",
        True,
        "every type 3 exception of every active task and every resource's fault enters the safe "
        f"procedure ({checked} cases)",
    )


def _nominal(a: Automaton, inputs: int) -> bool:
    p = a.program
    return not any(inputs >> i & 1 and p.input_kind[i] in ("T2", "T3", "fault") for i in range(len(p.inputs)))


def _abandons(a: Automaton, inputs: int) -> bool:
    """Whether an instant with `inputs` hands the run to the safe procedure: a type 3 exception
    or a resource's fault in it."""
    p = a.program
    return any(inputs >> i & 1 and p.input_kind[i] in ("T3", "fault") for i in range(len(p.inputs)))


def _backward(
    a: Automaton, g: _Graph, goal: Callable[[int, int, int], bool], keep: Callable[[int], bool]
) -> set[int]:
    """States from which a transition with goal(inputs, actions, next) is reachable over kept edges."""
    preds: dict[int, list[int]] = {}
    good: set[int] = set()
    for s, inputs, n, actions in g.edges():
        if not keep(inputs):
            continue
        if goal(inputs, actions, n):
            good.add(s)
        preds.setdefault(n, []).append(s)
    queue = deque(good)
    while queue:
        n = queue.popleft()
        for s in preds.get(n, []):
            if s not in good:
                good.add(s)
                queue.append(s)
    return good


def _check_liveness(a: Automaton, g: _Graph) -> CheckResult:

    def nominal(inputs: int) -> bool:
        return _nominal(a, inputs)

    can_succeed = _backward(a, g, lambda i, act, n: bool(act & a.success_bit), nominal)
    can_finish_safe = _backward(a, g, lambda i, act, n: bool(act & (a.safe_done_bit | a.failed_bit)), nominal)
    for s in g.parent:  # breadth-first order: the first stuck state has the shortest path
        if a.phase[s] == MAIN and s not in can_succeed:
            return CheckResult(
                "liveness", False, "success is unreachable from a reachable state without an exception",
                g.path(s), f"stuck at: {a.where[s]}",
            )  # fmt: skip
        if a.phase[s] == SAFE and s not in can_finish_safe:
            return CheckResult(
                "liveness", False, "the safe procedure cannot finish from a reachable state",
                g.path(s), f"stuck at: {a.where[s]}",
            )  # fmt: skip
    return CheckResult("liveness", True, "success stays reachable from every state, assuming no exceptions")


def _operator_moves(a: Automaton, s: int) -> bool:
    """Some operator input changes the reaction of this state (with no task active, its row holds
    operator inputs and resources' faults only; a fault is not awaited). An input the state tests
    without effect does not count: in the main procedure, the safe procedure's inputs are tested
    in every instant in case it is entered."""
    faults = a.program.fault_mask
    return len({hit for inputs, hit in a.table[s].items() if not inputs & faults}) > 1


def _idle(a: Automaton, s: int) -> bool:
    """Nothing outside can move this state: no active task, no operator input that changes it."""
    return a.phase[s] != END and not a.active[s] and not _operator_moves(a, s)


def _check_progress(a: Automaton, g: _Graph) -> CheckResult:
    for s in g.parent:
        if not _idle(a, s):
            continue
        seen: list[int] = []
        cur = s
        while _idle(a, cur) and cur not in seen:
            seen.append(cur)
            cur = a.table[cur][0][0]
        if cur in seen:
            loop = seen[seen.index(cur) :]
            kind = (
                "deadlock" if len(loop) == 1 and a.table[cur][0][1] == 0 else "a cycle that makes no progress"
            )
            return CheckResult(
                "deadlock", False, f"{kind}: nothing runs and no operator input is awaited",
                g.path(loop[0]), f"waiting at: {a.where[loop[0]]}",
            )  # fmt: skip
    return CheckResult("deadlock", True, "no deadlock, no cycle without a task or an operator input")


def _check_conflicts(a: Automaton, g: _Graph) -> CheckResult:
    tasks = a.program.tasks
    for s in g.parent:
        act = a.active[s]
        for i in range(len(act)):
            for j in range(i + 1, len(act)):
                t1, t2 = tasks[act[i]], tasks[act[j]]
                if t1.claims_overlap(t2):
                    what = f"resource {t1.resource}" + (
                        f" (joints {sorted(set(t1.joints) & set(t2.joints))})"
                        if t1.joints and t2.joints
                        else ""
                    )
                    pair = f"{t1.name} twice" if t1 is t2 else f"{t1.name} and {t2.name}"
                    return CheckResult(
                        "conflicts", False, f"{pair} active at once on {what}",
                        g.path(s), f"at: {a.where[s]}",
                    )  # fmt: skip
    return CheckResult("conflicts", True, "no two active tasks ever claim the same resource or joints")


def _check_one_task(a: Automaton, g: _Graph) -> CheckResult:
    tasks = a.program.tasks
    for s in sorted(g.parent):
        on: dict[str, list[str]] = {}
        for i in a.active[s]:
            on.setdefault(tasks[i].resource, []).append(tasks[i].name)
        for resource, names in on.items():
            if len(names) > 1:
                return CheckResult(
                    "one task per resource", False,
                    f"{' and '.join(names)} active at once on {resource}: the daemon runs one "
                    "Robot-Task at a time on each resource",
                    g.path(s), f"at: {a.where[s]}",
                )  # fmt: skip
    return CheckResult(
        "one task per resource", True,
        "at most one Robot-Task is active on each resource in any state (the daemon's need)",
    )  # fmt: skip


def _moves(a: Automaton, s: int, bit: int) -> bool:
    """The input `bit` alone changes state `s`'s reaction."""
    return a.react(s, bit) != a.react(s, 0)


def _check_peer_loss(a: Automaton, g: _Graph) -> CheckResult:
    """A state that waits for a peer's signal (it alone changes the reaction) must react to the
    loss of that peer too: otherwise a daemon that has gone leaves the mission waiting forever."""
    p = a.program
    lost = {peer: p.input_bit(name) for name, peer in p.lost_inputs}
    waits = [(p.input_bit(name), name, peer) for name, peer in p.remote_inputs]
    checked = 0
    for s in sorted(g.parent):
        for bit, name, peer in waits:
            if not _moves(a, s, bit):
                continue
            checked += 1
            if not _moves(a, s, lost[peer]):
                return CheckResult(
                    "peer loss", False,
                    f'{name} from "{peer}" is awaited where the loss of "{peer}" is not handled',
                    g.path(s),
                    f'waiting at: {a.where[s]}; handle it (`handle … on lost "{peer}" do … end`, '
                    f'or `do … until lost "{peer}"`)',
                )  # fmt: skip
    return CheckResult(
        "peer loss", True, f"every wait for a peer's signal reacts to that peer's loss ({checked} cases)"
    )


def _warnings(a: Automaton, g: _Graph) -> list[str]:
    out = []
    for s in sorted(g.parent):
        if a.phase[s] == MAIN and not a.active[s] and _operator_moves(a, s) and s != 0:
            trace = format_trace(a, g.path(s))
            out.append(f"nothing runs and only an operator input can move the mission at: {a.where[s]} "
                       f"(reached by: {'; '.join(trace)})")  # fmt: skip
    return out[:5]


# strong liveness ----------------------------------------------------------------------------------

_ASSUMED = (
    "every active task ends (its postcondition, a type 2 or a type 3 exception: tasks time out); "
    "operator inputs and resources' faults may never come"
)

Edge = tuple[int, int, int, int]  # (state, inputs, next state, actions)


@dataclass
class _Loop:
    """A cycle a procedure can run through forever under the environment assumptions."""

    states: set[int]
    entry: int  # its state reached first from the initial state
    error: bool  # nothing runs in it and nothing can leave it: the program spins or halts
    summary: str


def _check_strong_liveness(a: Automaton, g: _Graph) -> CheckResult:
    loops = [loop for phase in (MAIN, SAFE) if (loop := _endless_loop(a, g, phase)) is not None]
    if not loops:
        return CheckResult(
            "strong liveness", True,
            "every run of each procedure ends (main: success or safe; safe: done or failed), assuming "
            + _ASSUMED,
        )  # fmt: skip
    worst = next((loop for loop in loops if loop.error), loops[0])
    prefix, cycle = g.path(worst.entry), _fair_cycle(a, worst)
    others = [loop.summary for loop in loops if loop is not worst]
    why = (
        "the program spins or halts: nothing runs in the loop and no input leads out of it"
        if worst.error
        else "a note, not a failure: in the loop a task runs or an input can lead out"
    )
    explanation = "\n".join([why, f"assumed: {_ASSUMED}", *(f"also: {o}" for o in others)])
    return CheckResult(
        "strong liveness", False, worst.summary, [*prefix, *cycle], explanation,
        level=ERROR if worst.error else NOTE, loop_start=len(prefix),
    )  # fmt: skip


def _must_end(a: Automaton, t: int) -> bool:
    """The fairness assumption covers task t: it ends within its timeout. A task from a task file
    without the type 3 `Timeout` (`timeout_s = inf`) may run forever."""
    info = a.program.tasks[t]
    return not info.source or any(full.endswith(f".T3.{TASK_TIMEOUT}") for _, full, _ in info.events)


def _inside(a: Automaton, states: set[int], s: int) -> list[Edge]:
    return [(s, inputs, n, act) for inputs, (n, act) in a.table[s].items() if n in states]


def _endless_loop(a: Automaton, g: _Graph, phase: int) -> _Loop | None:
    """The worst fair cycle of one procedure that never ends it (an error first), the one reached
    first from the initial state; None if every run of the procedure ends."""
    order = {s: i for i, s in enumerate(g.parent)}
    nodes = [s for s in g.parent if a.phase[s] == phase]

    def succ(s: int) -> list[int]:
        return [n for n, _ in a.table[s].values() if a.phase[n] == phase]

    found: list[_Loop] = []
    for comp in _sccs(nodes, succ):
        states = set(comp)
        if _is_fair_cycle(a, states):
            found.append(_describe_loop(a, states, min(states, key=order.__getitem__), phase))
    if not found:
        return None
    return min(found, key=lambda loop: (not loop.error, order[loop.entry]))


def _is_fair_cycle(a: Automaton, states: set[int]) -> bool:
    """The strongly connected `states` hold a cycle along which every task that must end does:
    each task active in all of them is stopped by some transition among them."""
    edges = [e for s in states for e in _inside(a, states, s)]
    if not edges:
        return False  # a single state without a loop on itself
    always = set.intersection(*(set(a.active[s]) for s in states))
    stopped = 0
    for _, _, _, act in edges:
        stopped |= a.stops(act)
    return all(stopped >> t & 1 for t in always if _must_end(a, t))


def _describe_loop(a: Automaton, states: set[int], entry: int, phase: int) -> _Loop:
    p = a.program
    proc = next(d.name for d in p.ast.procedures if d.role == ("main" if phase == MAIN else "safe"))
    who = f"the {'main' if phase == MAIN else 'safe'} procedure {proc}"
    exits = [  # a resource's fault is no way out: it may never come
        (inputs, act)
        for s in states
        for inputs, (n, act) in a.table[s].items()
        if n not in states and not inputs & p.fault_mask
    ]
    busy = any(p.tasks[t].runs for s in states for t in a.active[s])
    if not exits and not busy:
        return _Loop(states, entry, True, f"{who} can run forever with nothing running and no way out")
    if not exits:
        return _Loop(states, entry, False, f"{who} never ends: it runs tasks in a loop with no way out")
    if any(inputs == 0 for inputs, _ in exits):
        kept = f"{who} may run forever: inputs can keep it in a loop it leaves when none comes"
        return _Loop(states, entry, False, kept)
    ways = _exit_inputs(a, exits)
    operator = [n for n in ways if p.input_kind[p.inputs.index(n)] == "operator"]
    if operator:
        waits = f"{who} may wait forever for an operator input ({', '.join(operator)})"
        return _Loop(states, entry, False, waits)
    if ways:
        return _Loop(states, entry, False, f"{who} may run forever: it loops until {' or '.join(ways)}")
    return _Loop(states, entry, False, f"{who} may run forever: only a type 3 exception leaves its loop")


def _exit_inputs(a: Automaton, exits: list[tuple[int, int]]) -> list[str]:
    """The inputs (other than type 3 exceptions) that leave a loop: those that do alone, or else
    every input of a leaving combination."""
    p = a.program
    alone = {inputs for inputs, _ in exits if inputs & (inputs - 1) == 0}
    masks = alone or {inputs for inputs, _ in exits}
    bits = 0
    for m in masks:
        bits |= m
    return [n for i, n in enumerate(p.inputs) if bits >> i & 1 and p.input_kind[i] not in ("T3", "fault")]


def _fair_cycle(a: Automaton, loop: _Loop) -> list[Step]:
    """A cycle from the loop's entry back to it along which every task active at the entry that
    must end is stopped or seen inactive: shortest paths, one obligation after the other."""
    pending = {t for t in a.active[loop.entry] if _must_end(a, t)}
    cur, path = loop.entry, []
    while pending:
        leg = _shortest(a, loop.states, cur, partial(_discharges, a, tasks=frozenset(pending)))
        for e in leg:
            pending -= {t for t in pending if _discharges(a, e, {t})}
        path.extend(leg)
        cur = leg[-1][2]
    if cur != loop.entry or not path:
        path.extend(_shortest(a, loop.states, cur, lambda e: e[2] == loop.entry))
    return [Step(inputs, act) for _, inputs, _, act in path]


def _discharges(a: Automaton, e: Edge, tasks: Set[int]) -> bool:
    """Transition e stops one of `tasks`, or leads to a state where one of them is not active."""
    return any(a.stops(e[3]) >> t & 1 or t not in a.active[e[2]] for t in tasks)


def _shortest(a: Automaton, states: set[int], start: int, goal: Callable[[Edge], bool]) -> list[Edge]:
    """The shortest path inside `states` from `start` whose last transition satisfies `goal`
    (transitions tried in input order: the empty input first)."""
    came: dict[int, Edge | None] = {start: None}
    queue = deque([start])
    while queue:
        s = queue.popleft()
        for e in _inside(a, states, s):
            if goal(e):
                path = [e]
                while (back := came[path[-1][0]]) is not None:
                    path.append(back)
                return path[::-1]
            if e[2] not in came:
                came[e[2]] = e
                queue.append(e[2])
    raise AssertionError("a strongly connected set has a path between any two of its states")


def _sccs(nodes: list[int], succ: Callable[[int], list[int]]) -> list[list[int]]:
    """Strongly connected components (Tarjan's algorithm, iterative: no recursion limit)."""
    index: dict[int, int] = {}
    low: dict[int, int] = {}
    stack: list[int] = []
    on_stack: set[int] = set()
    out: list[list[int]] = []
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(succ(root)))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next((w for w in it if w not in index or w in on_stack), None)
            if w is not None and w not in index:
                index[w] = low[w] = len(index)
                stack.append(w)
                on_stack.add(w)
                work.append((w, iter(succ(w))))
                continue
            if w is not None:
                low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp: list[int] = []
                while not comp or comp[-1] != v:
                    comp.append(stack.pop())
                    on_stack.discard(comp[-1])
                out.append(comp)
    return out


# dead code ----------------------------------------------------------------------------------------


def _check_dead_code(a: Automaton) -> CheckResult:
    try:
        executed = executed_sites(a)
    except CoverageError as e:
        return CheckResult("dead code", False, f"not checked: {e}", level=WARNING)
    return dead_code_result(a.program, executed)


def dead_code_result(p: Program, executed: set[int]) -> CheckResult:
    """The dead-code check given the sites (indices in `p.sites`) some reachable reaction executes."""
    items = [(site.loc, f"{site.what} {_NEVER[site.kind]}") for site in _dead_sites(p.sites, executed)]
    run = {site.what for site in p.sites if site.kind == "task"}
    unused = [t for t in p.tasks if f"task {t.name}" not in run]
    items += [(t.loc, f"task {t.name} is declared but never run") for t in unused]
    if not items:
        return CheckResult("dead code", True, "every task activation, emit and branch can run")
    items.sort(key=lambda item: (item[0].line, item[0].col))
    noun = "statement" if len(items) == 1 else "statements"
    return CheckResult(
        "dead code", False, f"{len(items)} {noun} no reachable state can start or emit",
        explanation="\n".join(f"{loc}: {text}" for loc, text in items), level=WARNING,
    )  # fmt: skip


_NEVER = {
    "task": "never starts",
    "emit": "is never executed",
    "branch": "never runs",
    "safe": "is never entered",
}


def _dead_sites(sites: tuple[Site, ...], executed: set[int]) -> list[Site]:
    """The sites to report: every copy of the statement (a procedure is expanded at each call) is
    dead, and some copy is not inside a dead branch (else that branch is reported instead)."""
    copies: dict[tuple[str, str, A.Loc], list[int]] = {}
    for i, site in enumerate(sites):
        copies.setdefault((site.kind, site.what, site.loc), []).append(i)
    out = []
    for group in copies.values():
        if any(i in executed for i in group):
            continue
        if any(sites[i].parent < 0 or sites[i].parent in executed for i in group):
            out.append(sites[group[0]])
    return out


# observers ----------------------------------------------------------------------------------------


Prev = tuple[int, int]  # the previous instant's inputs and actions, as far as a `pre(S)` reads them


def _atom_holds(a: Automaton, e: A.SigExpr, inputs: int, actions: int, nxt: int, prev: Prev = (0, 0)) -> bool:
    p = a.program
    if isinstance(e, A.SigRef):
        name = p.signal(e.name)
        if name in p.inputs:
            return bool(inputs >> p.inputs.index(name) & 1)
        return bool(actions >> (a.emit_base + p.internals.index(name)) & 1)
    if isinstance(e, A.Fn) and e.fn == "pre":  # S in the previous instant (absent before the first)
        return _atom_holds(a, A.SigRef(e.arg, e.loc), prev[0], prev[1], nxt)
    if isinstance(e, A.Fn):
        t = [x.name for x in p.tasks].index(e.arg)
        if e.fn == "active":
            return t in a.active[nxt]
        base = a.start_base if e.fn == "start" else a.stop_base
        return bool(actions >> (base + t) & 1)
    if isinstance(e, A.Not):
        return not _atom_holds(a, e.item, inputs, actions, nxt, prev)
    if isinstance(e, A.And):
        return all(_atom_holds(a, x, inputs, actions, nxt, prev) for x in e.items)
    return any(_atom_holds(a, x, inputs, actions, nxt, prev) for x in e.items)


def _pre_masks(a: Automaton, e: A.SigExpr | None) -> Prev:
    """(input bits, action bits) the `pre(S)` atoms of `e` read: what an observer remembers."""
    if e is None:
        return 0, 0
    p = a.program
    if isinstance(e, A.Fn) and e.fn == "pre":
        name = p.signal(e.arg)
        if name in p.inputs:
            return 1 << p.inputs.index(name), 0
        return 0, 1 << (a.emit_base + p.internals.index(name))
    if isinstance(e, A.Not):
        return _pre_masks(a, e.item)
    if isinstance(e, A.And | A.Or):
        pin = pact = 0
        for x in e.items:
            i, k = _pre_masks(a, x)
            pin, pact = pin | i, pact | k
        return pin, pact
    return 0, 0


def _check_property(a: Automaton, g: _Graph, prop: A.PropDecl) -> CheckResult:
    name = f"property {prop.name}"
    pin_a, pact_a = _pre_masks(a, prop.a)
    pin_b, pact_b = _pre_masks(a, prop.b)
    pin, pact = pin_a | pin_b, pact_a | pact_b  # a `pre` observer: the instant before, remembered

    def holds(e: A.SigExpr, inputs: int, actions: int, n: int, prev: Prev = (0, 0)) -> bool:
        return _atom_holds(a, e, inputs, actions, n, prev)

    if prop.kind == "never" and not (pin or pact):
        for s, inputs, n, actions in g.edges():
            if holds(prop.a, inputs, actions, n):
                return CheckResult(
                    name,
                    False,
                    "violated: the forbidden situation is reachable",
                    [*g.path(s), Step(inputs, actions)],
                )
        return CheckResult(name, True, "never happens")
    # product of the automaton with an observer (two states, and the instant before for a `pre`),
    # breadth first for short counterexamples
    Node = tuple[int, int, Prev]
    start: Node = (0, 0, (0, 0))
    parent: dict[Node, tuple[Node, Step]] = {}
    seen = {start}
    queue = deque([start])
    bad: tuple[Node, Step | None, str] | None = None
    b = prop.b if prop.b is not None else prop.a
    if prop.kind == "eventually" and (pin_b or pact_b):
        return CheckResult(
            name, False, f"`pre(...)` in what must eventually happen ({A.show(b)}): not supported"
        )

    # `-> eventually` is a liveness property: checked, as liveness is, on the runs that no type 3
    # exception or resource fault hands to the safe procedure (those are safety's); `never` and
    # `alternate` hold on every run
    def kept(inputs: int) -> bool:
        return prop.kind != "eventually" or not _abandons(a, inputs)

    eventually = prop.kind == "eventually"
    can_b = _backward(a, g, lambda i, act, n: holds(b, i, act, n), kept) if eventually else set()
    while queue and bad is None:
        node = queue.popleft()
        s, obs, prev = node
        if prop.kind == "eventually" and obs == 1 and (a.phase[s] == END or s not in can_b):
            why = "can no longer happen" if a.phase[s] != END else "did not happen before the mission ended"
            bad = (node, None, f"after {A.show(prop.a)}, {A.show(b)} {why}")
            break
        for inputs, (n, actions) in a.table[s].items():
            if not kept(inputs):
                continue
            ha, hb = holds(prop.a, inputs, actions, n, prev), holds(b, inputs, actions, n, prev)
            step = Step(inputs, actions)
            if prop.kind == "never":
                if ha:
                    bad = (node, step, "the forbidden situation is reachable")
                    break
                nobs = 0
            elif prop.kind == "eventually":
                nobs = 0 if hb else (1 if (ha or obs == 1) else 0)
            else:  # alternate: A first; an instant with both counts as B then A
                if obs == 0 and hb:
                    bad = (node, step, f"{A.show(b)} without {A.show(prop.a)} before it")
                    break
                if obs == 1 and ha and not hb:
                    bad = (node, step, f"{A.show(prop.a)} twice without {A.show(b)} between")
                    break
                nobs = 1 if ha else (0 if hb else obs)
            nxt = (n, nobs, (inputs & pin, actions & pact))
            if nxt not in seen:
                seen.add(nxt)
                parent[nxt] = (node, step)
                queue.append(nxt)
    if bad is None:
        return CheckResult(name, True, "holds in every reachable state")
    node, last, why = bad
    trace: list[Step] = [] if last is None else [last]
    while node != start:
        node, st = parent[node]
        trace.append(st)
    trace.reverse()
    return CheckResult(name, False, f"violated: {why}", trace)
