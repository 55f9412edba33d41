"""Which emission depends on which test in the same instant: names the cycle of a non-causal program."""

from __future__ import annotations

from dataclasses import dataclass

from orccadd.automaton.language import ast as A


@dataclass(frozen=True)
class Dependency:
    tested: str  # an internal signal tested ...
    tested_at: A.Loc
    emitted: str  # ... before this one is emitted in the same instant
    emitted_at: A.Loc


def dependencies(m: A.MissionAst, internals: tuple[str, ...]) -> list[Dependency]:
    procs = {p.name: p for p in m.procedures}
    out: list[Dependency] = []

    def signals(e: A.SigExpr | None) -> list[tuple[str, A.Loc]]:
        if e is None:
            return []
        if isinstance(e, A.SigRef):
            return [(e.name, e.loc)] if e.name in internals else []
        if isinstance(e, A.Fn):
            return []
        if isinstance(e, A.Not):
            return signals(e.item)
        return [s for i in e.items for s in signals(i)]

    def walk(s: A.Stmt, guards: list[tuple[str, A.Loc]], stack: tuple[str, ...]) -> None:
        if isinstance(s, A.Emit) and s.name in internals:
            out.extend(Dependency(g, gl, s.name, s.loc) for g, gl in guards)
        elif isinstance(s, A.Call) and s.name in procs and s.name not in stack:
            p = procs[s.name]
            walk(p.body, guards, (*stack, s.name))
            for h in p.handlers:
                walk(h.body, guards + signals(h.cond), (*stack, s.name))
        elif isinstance(s, A.Seq):
            acc = list(guards)
            for item in s.items:
                walk(item, acc, stack)
                # what follows runs once the item ends, which may hang on what it tests (an
                # await's condition, a `present`'s: constructive semantics)
                acc = acc + tests_in(item)
        elif isinstance(s, A.Present):
            g = guards + signals(s.cond)
            for sub in A.substatements(s):
                walk(sub, g, stack)
        elif isinstance(s, A.When | A.Every):
            g = guards + signals(s.cond) + (signals(s.until) if isinstance(s, A.When) else [])
            walk(s.body, g, stack)
        elif isinstance(s, A.DoUntil):
            walk(s.body, guards if s.weak else guards + signals(s.cond), stack)
        elif isinstance(s, A.Suspend):
            walk(s.body, guards + signals(s.cond), stack)
        elif isinstance(s, A.Handle):
            conds = [x for h in s.handlers for x in signals(h.cond)]
            walk(s.body, guards + conds, stack)
            for h in s.handlers:
                walk(h.body, guards + conds, stack)
        else:
            for sub in A.substatements(s):
                walk(sub, guards, stack)

    def tests_in(s: A.Stmt) -> list[tuple[str, A.Loc]]:
        out = [x for c in _conds(s) for x in signals(c)]
        for sub in A.substatements(s):
            out += tests_in(sub)
        return out

    for p in m.procedures:
        walk(p.body, [], (p.name,))
        for h in p.handlers:
            walk(h.body, signals(h.cond), (p.name,))
    return out


def _conds(s: A.Stmt) -> list[A.SigExpr | None]:
    """The conditions a statement itself tests."""
    if isinstance(s, A.Present | A.Await | A.DoUntil | A.Suspend | A.Every):
        return [s.cond]
    if isinstance(s, A.When):
        return [s.cond, s.until]
    return []


def find_cycle(deps: list[Dependency], among: set[str]) -> list[Dependency]:
    """A cycle of same-instant dependencies among the given signals (empty if there is none)."""
    succ: dict[str, list[Dependency]] = {}
    for d in deps:
        if d.tested in among and d.emitted in among:
            succ.setdefault(d.tested, []).append(d)

    def dfs(node: str, path: list[Dependency], seen: set[str]) -> list[Dependency]:
        for d in succ.get(node, []):
            if (path and d.emitted == path[0].tested) or (not path and d.emitted == node):
                return [*path, d]
            if d.emitted not in seen:
                found = dfs(d.emitted, [*path, d], seen | {d.emitted})
                if found:
                    return found
        return []

    for start in sorted(succ):
        cycle = dfs(start, [], {start})
        if cycle:
            return cycle
    return []
