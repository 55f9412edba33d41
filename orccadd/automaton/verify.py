"""Checks on the explicit automaton, each failure with a counterexample (a sequence of instants).

- determinism: every reachable instant has exactly one reaction (guaranteed by the compiler,
  which refuses non-causal programs and instantaneous loops);
- deadlock and non-progress: no state that nothing can move (no active task, no operator input
  awaited), no cycle the program runs through on its own without a task or an operator input;
- safety: in every reachable state, a type 3 exception of any active Robot-Task enters the safe
  procedure in the same instant (or, inside the safe procedure, ends the mission as failed);
- liveness: with no exceptions (no T2, no T3), success stays reachable from every reachable state
  of the main procedure (the end of the safe procedure from every state of it);
- conflicts: no reachable state has two active tasks claiming the same resource or joints;
- the mission's own properties (observers): `never E`, `A -> eventually B`, `A and B alternate`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from orccadd.automaton import ast as A
from orccadd.automaton.automaton import END, MAIN, SAFE, Automaton


@dataclass(frozen=True)
class Step:
    inputs: int
    actions: int


@dataclass
class CheckResult:
    name: str
    ok: bool
    summary: str
    counterexample: list[Step] = field(default_factory=list)
    explanation: str = ""


@dataclass
class Report:
    automaton: Automaton
    results: list[CheckResult]
    warnings: list[str]

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.results)

    def failed(self, name: str) -> bool:
        return any(r.name == name and not r.ok for r in self.results)

    def format(self) -> str:
        a = self.automaton
        lines = [f"mission {a.program.name}: {a.n_states} states, {a.n_transitions} transitions"]
        for r in self.results:
            lines.append(f"  {'ok  ' if r.ok else 'FAIL'} {r.name}: {r.summary}")
            if not r.ok and r.counterexample:
                lines.append("       counterexample:")
                lines.extend("         " + s for s in format_trace(a, r.counterexample))
            if not r.ok and r.explanation:
                lines.append(f"       {r.explanation}")
        lines.extend(f"  note: {w}" for w in self.warnings)
        return "\n".join(lines)


def format_trace(a: Automaton, trace: list[Step]) -> list[str]:
    p = a.program
    out = []
    for i, st in enumerate(trace, start=1):
        acts = ", ".join(a.describe_actions(st.actions)) or "-"
        out.append(f"instant {i}: inputs {p.describe_inputs(st.inputs)} -> {acts}")
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


def verify(a: Automaton, *, one_task_at_a_time: bool = False) -> Report:
    """Every check; `one_task_at_a_time` adds the execution machine's own need (the daemon runs
    one Robot-Task at a time on its robot: `orccadd.mission.check_mission`)."""
    g = _Graph(a)
    results = [
        CheckResult(
            "determinism", True, f"every reachable instant has exactly one reaction ({len(g.parent)} states)"
        ),
        _check_progress(a, g),
        _check_safety(a, g),
        _check_liveness(a, g),
        _check_conflicts(a, g),
    ]
    if one_task_at_a_time:
        results.append(_check_one_task(a, g))
    results.extend(_check_property(a, g, prop) for prop in a.program.properties)
    return Report(a, results, _warnings(a, g))


def _t3_of_active(a: Automaton, s: int) -> int:
    m = 0
    for t in a.active[s]:
        m |= a.program.t3_masks[t]
    return m


def _check_safety(a: Automaton, g: _Graph) -> CheckResult:
    handled = a.safe_bit | a.failed_bit
    checked = 0
    for s, inputs, _, actions in g.edges():
        if inputs & _t3_of_active(a, s):
            checked += 1
            if not actions & handled:
                names = [
                    n
                    for i, n in enumerate(a.program.inputs)
                    if inputs >> i & 1 and a.program.input_kind[i] == "T3"
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
        f"every type 3 exception of every active task enters the safe procedure ({checked} cases)",
    )


def _nominal(a: Automaton, inputs: int) -> bool:
    p = a.program
    return not any(inputs >> i & 1 and p.input_kind[i] in ("T2", "T3") for i in range(len(p.inputs)))


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


def _idle(a: Automaton, s: int) -> bool:
    """Nothing outside can move this state: no active task, no operator input it reacts to."""
    return a.phase[s] != END and not a.active[s] and not (a.relevant[s] & a.program.operator_mask)


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
    for s in sorted(g.parent):
        if len(a.active[s]) > 1:
            names = " and ".join(a.program.tasks[i].name for i in a.active[s])
            return CheckResult(
                "one task", False, f"{names} active at once: the daemon runs one Robot-Task at a time",
                g.path(s), f"at: {a.where[s]}",
            )  # fmt: skip
    return CheckResult("one task", True, "at most one Robot-Task is active in any state (the daemon's need)")


def _warnings(a: Automaton, g: _Graph) -> list[str]:
    out = []
    for s in sorted(g.parent):
        if a.phase[s] == MAIN and not a.active[s] and (a.relevant[s] & a.program.operator_mask) and s != 0:
            trace = format_trace(a, g.path(s))
            out.append(f"nothing runs and only an operator input can move the mission at: {a.where[s]} "
                       f"(reached by: {'; '.join(trace)})")  # fmt: skip
    return out[:5]


# observers ----------------------------------------------------------------------------------------


def _atom_holds(a: Automaton, e: A.SigExpr, inputs: int, actions: int, nxt: int) -> bool:
    p = a.program
    if isinstance(e, A.SigRef):
        name = p.signal(e.name)
        if name in p.inputs:
            return bool(inputs >> p.inputs.index(name) & 1)
        return bool(actions >> (a.emit_base + p.internals.index(name)) & 1)
    if isinstance(e, A.Fn):
        t = [x.name for x in p.tasks].index(e.arg)
        if e.fn == "active":
            return t in a.active[nxt]
        base = a.start_base if e.fn == "start" else a.stop_base
        return bool(actions >> (base + t) & 1)
    if isinstance(e, A.Not):
        return not _atom_holds(a, e.item, inputs, actions, nxt)
    if isinstance(e, A.And):
        return all(_atom_holds(a, x, inputs, actions, nxt) for x in e.items)
    return any(_atom_holds(a, x, inputs, actions, nxt) for x in e.items)


def _check_property(a: Automaton, g: _Graph, prop: A.PropDecl) -> CheckResult:
    name = f"property {prop.name}"

    def holds(e: A.SigExpr, inputs: int, actions: int, n: int) -> bool:
        return _atom_holds(a, e, inputs, actions, n)

    if prop.kind == "never":
        for s, inputs, n, actions in g.edges():
            if holds(prop.a, inputs, actions, n):
                return CheckResult(
                    name,
                    False,
                    "violated: the forbidden situation is reachable",
                    [*g.path(s), Step(inputs, actions)],
                )
        return CheckResult(name, True, "never happens")
    assert prop.b is not None
    # product of the automaton with a two-state observer, breadth first for short counterexamples
    start = (0, 0)
    parent: dict[tuple[int, int], tuple[tuple[int, int], Step]] = {}
    seen = {start}
    queue = deque([start])
    bad: tuple[tuple[int, int], Step | None, str] | None = None
    b = prop.b
    can_b = (
        _backward(a, g, lambda i, act, n: holds(b, i, act, n), lambda i: True)
        if prop.kind == "eventually"
        else set()
    )
    while queue and bad is None:
        node = queue.popleft()
        s, obs = node
        if prop.kind == "eventually" and obs == 1 and (a.phase[s] == END or s not in can_b):
            why = "can no longer happen" if a.phase[s] != END else "did not happen before the mission ended"
            bad = (node, None, f"after {A.show(prop.a)}, {A.show(prop.b)} {why}")
            break
        for inputs, (n, actions) in a.table[s].items():
            ha, hb = holds(prop.a, inputs, actions, n), holds(prop.b, inputs, actions, n)
            step = Step(inputs, actions)
            if prop.kind == "eventually":
                nobs = 0 if hb else (1 if (ha or obs == 1) else 0)
            else:  # alternate: A first; an instant with both counts as B then A
                if obs == 0 and hb:
                    bad = (node, step, f"{A.show(prop.b)} without {A.show(prop.a)} before it")
                    break
                if obs == 1 and ha and not hb:
                    bad = (node, step, f"{A.show(prop.a)} twice without {A.show(prop.b)} between")
                    break
                nobs = 1 if ha else (0 if hb else obs)
            nxt = (n, nobs)
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
