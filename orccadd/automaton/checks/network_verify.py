"""Verifying a `Network` (compiler/network.py) without its product: the checks run on small products.

Each product is an ordinary explicit automaton, checked by `verify`: the context (exactly), the
branches the check needs (exactly: by default one, a property the branches it mentions), and the
other branches standing as **one task** that may end, or exit any trap they can exit, at any
instant or never (only what they can do: end only if each of them can, in their first instant
only if each can). The branches share no task, resource, input or signal, so what one branch and
the context can do with the others is exactly what they can do with that stand-in, and a
verdict holds for the mission when it holds in every product:

- safety, conflicts, determinism, progress: a reachable state of the mission is a reachable state
  of each branch's product (the others' part abstracted); conflicts between branches cannot
  happen (their resources are disjoint, `find_split`);
- liveness ("success stays reachable"): each product's, the stand-in ending when its branches
  can (each can, on its own inputs, independently of the others);
- strong liveness: the stand-in is a task, covered by the same fairness assumption as any task
  (it ends; its branches are checked to end in their own products);
- dead code: a statement is executed when some product executes it (the union);
- a property: in the product of the branches it mentions.

A product's counterexample is a run of the mission (the stand-in's start, stop and inputs read as
"the other branches"). Over-approximation can only refuse more: a counterexample that needs the
other branches to behave as no real run does is possible in principle (they are abstracted),
never a verdict of "ok" that does not hold. So a counterexample that goes through the stand-in
says so in words (`_stand_in_words`): what its event means (the others ended, stopped for good,
exited) and the shortest run of each of them that gets there, on their own inputs — the product's
instants are not theirs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from orccadd.automaton.checks.coverage import CoverageError, executed_sites
from orccadd.automaton.checks.verify import (
    ERROR,
    NOTE,
    WARNING,
    CheckResult,
    Report,
    _is_fair_cycle,
    _sccs,
    dead_code_result,
    verify,
)
from orccadd.automaton.compiler.automaton import END, Automaton
from orccadd.automaton.compiler.explicit import DEFAULT_MAX_STATES, compile_program
from orccadd.automaton.compiler.network import Network, _emits, remap_sites, substitute
from orccadd.automaton.language import ast as A
from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.program import Program, TaskInfo


@dataclass(frozen=True)
class _Others:
    """What the branches outside a product can do, as seen from the par and the context."""

    branches: tuple[int, ...]
    done: bool  # each can end
    exits: tuple[int, ...]  # the trap codes some can exit with
    now_done: str  # in their first instant: "must" (each always ends then), "may" (each can), ""
    now_exits: tuple[int, ...]  # the codes some can exit with in its first instant
    must_exit: int  # the least code the par surely exits with in their first instant (0: none)
    seen: tuple[tuple[str, int], ...]  # (kind, input bit): their tasks' events the context tests
    surely_end: bool  # every run of each ends, assuming its tasks end (no fair cycle on its own)
    run_tasks: bool  # some of them runs a task at some point
    may_idle: bool  # each can end or get stuck with nothing running and no way out (not surely_end)


def _others(net: Network, members: tuple[int, ...]) -> _Others | None:
    rest = tuple(b for b in range(len(net.branches)) if b not in members)
    if not rest:
        return None
    p = net.program
    done, all_may, all_must = True, True, True
    exits: set[int] = set()
    now_exits: set[int] = set()
    must_exit = 0
    for b in rest:
        a = net.branches[b]
        first = {net.codes[act >> net.code_shift] for _, act in a.table[0].values()}
        every = {net.codes[act >> net.code_shift] for row in a.table[:-1] for _, act in row.values()}
        done &= K.DONE in every
        all_may &= K.DONE in first
        all_must &= first == {K.DONE}
        exits |= {c for c in every if c > K.PAUSED}
        now_exits |= {c for c in first if c > K.PAUSED}
        if first and min(first) > K.PAUSED:
            must_exit = max(must_exit, min(first))
    tasks = {t for b in rest for act in net.branches[b].active for t in act}  # tasks they can run
    events = 0
    for t in tasks:
        events |= p.event_masks[t]
    seen = []
    for bits, _ in net.hole_classes:
        mine = bits & events
        if mine:
            rep = mine & -mine
            seen.append((p.input_kind[rep.bit_length() - 1], rep))
    now = "must" if all_must else "may" if all_may else ""
    loops = [_fair_loops(net.branches[b]) for b in rest]
    surely = not any(loops)
    stuck = [any(_stuck(net.branches[b], c) for c in ls) for b, ls in zip(rest, loops, strict=True)]
    # all of them idle forever: some stuck, the others stuck or ended
    may_idle = any(stuck) and all(x or K.DONE in _codes(net, b) for b, x in zip(rest, stuck, strict=True))
    run_tasks = any(act for b in rest for act in net.branches[b].active)
    return _Others(
        rest,
        done,
        tuple(sorted(exits)),
        now,
        tuple(sorted(now_exits)),
        must_exit,
        tuple(seen),
        surely,
        run_tasks,
        may_idle,
    )


def _codes(net: Network, b: int) -> set[int]:
    return {net.codes[act >> net.code_shift] for row in net.branches[b].table[:-1] for _, act in row.values()}


def _fair_loops(a: Automaton) -> list[set[int]]:
    """The cycles a branch on its own can run through forever under the fairness assumption
    (`verify`'s strong liveness: its tasks end; operator inputs may never come)."""
    live = [s for s in range(a.n_states) if a.phase[s] != END]
    comps = _sccs(live, lambda s: [n for n, _ in a.table[s].values() if a.phase[n] != END])
    return [set(c) for c in comps if _is_fair_cycle(a, set(c))]


def _stuck(a: Automaton, loop: set[int]) -> bool:
    """In this loop nothing runs and no input leads out (strong liveness's error)."""
    return not any(a.active[s] for s in loop) and all(n in loop for s in loop for n, _ in a.table[s].values())


def _exit_name(code: int) -> str:
    return "safe" if code == K.SAFE_CODE else f"exit{code}"


def branch_names(net: Network, branches: tuple[int, ...]) -> str:
    which = ", ".join(str(b + 1) for b in branches)
    noun = "branches" if len(branches) > 1 else "branch"
    return f"{noun} {which} of the par at line {net.split.loc.line}"


def product_program(net: Network, members: tuple[int, ...], properties: tuple[A.PropDecl, ...]) -> Program:
    """The mission with the par reduced to the branches `members` and, for the others, one task
    (see the module docstring); keeps every input bit, task index and dead-code site of `p`."""
    p, split = net.program, net.split
    branches: list[K.Term | None] = [split.branches[b] for b in members]
    others = _others(net, members)
    fields: dict[str, object] = {}
    if others is not None:
        stand_in, fields = _stand_in(p, split.loc, others, f"({branch_names(net, others.branches)})")
        branches.append(stand_in)
    main, rebuilt = substitute(p.main, split.par, K.Par(tuple(branches)))
    return dataclasses.replace(
        p,
        main=main,
        sites=remap_sites(p.sites, rebuilt),
        properties=properties,
        **fields,  # type: ignore[arg-type]
    )


def _stand_in(p: Program, loc: A.Loc, o: _Others, name: str) -> tuple[K.Term, dict[str, object]]:
    """The task standing for the other branches: its term in the par and the program's new fields.
    It ends (`done`) only if each of them can, exits what they can exit (events of its own), raises
    the events of theirs the context tests (their own input bits), and in its first instant ends
    or exits as they can then (operator inputs of its own, or at once where they must)."""
    task = len(p.tasks)
    ends = [("done", K.DONE)] if o.done else []
    ends += [("idle", K.PAUSED)] if o.may_idle else []  # then stuck: nothing runs, no way out
    ends += [(_exit_name(c), c) for c in o.exits]
    end_bits = [1 << (len(p.inputs) + i) for i in range(len(ends))]
    events = [("post", f"{name}.{label}", bit) for (label, _), bit in zip(ends, end_bits, strict=True)]
    events += [(kind, p.inputs[bit.bit_length() - 1], bit) for kind, bit in o.seen]
    now = [("done", K.DONE)] if o.now_done == "may" else []
    now += [(_exit_name(c), c) for c in o.now_exits if c > o.must_exit]
    base = len(p.inputs) + len(ends)
    now_bits = [1 << (base + i) for i in range(len(now))]
    term: K.Term = K.Run(task, loc)
    exits = [(bit, code) for bit, (_, code) in zip(end_bits, ends, strict=True) if code > K.PAUSED]
    if exits:
        term = K.Handle(
            term, tuple((K.IN, bit) for bit, _ in exits), tuple(K.Exit(code) for _, code in exits)
        )
    for bit, (_, code) in zip(end_bits, ends, strict=True):
        if code == K.PAUSED:
            term = K.seq((term, K.Present((K.IN, bit), K.Halt(loc), K.NOTHING)))
    if o.now_done == "must":
        term = K.NOTHING
    if o.must_exit:
        term = K.Exit(o.must_exit)
    for bit, (_, code) in reversed(list(zip(now_bits, now, strict=True))):
        term = K.Present((K.IN, bit), K.NOTHING if code == K.DONE else K.Exit(code), term)
    end_mask = sum(end_bits)
    event_mask = end_mask | sum(bit for _, bit in o.seen)
    t3 = sum(bit for kind, bit in o.seen if kind == "T3")
    names = dict(p.names)
    new_inputs = [full for _, full, _ in events[: len(ends)]] + [
        f"{name}.at_once.{label}" for label, _ in now
    ]
    for full in new_inputs:
        names[full] = (full,)
    # assumed to end (the fairness of strong liveness) only if the branches it stands for surely end
    source = "" if o.surely_end else "(branches)"
    info = TaskInfo(task, name, name, (), source, loc, tuple(events), runs=o.run_tasks)
    return term, {
        "inputs": (*p.inputs, *new_inputs),
        "input_task": (*p.input_task, *(task for _ in ends), *(-1 for _ in now)),
        "input_kind": (*p.input_kind, *("post" for _ in ends), *("operator" for _ in now)),
        "tasks": (*p.tasks, info),
        "operator_mask": p.operator_mask | sum(now_bits),
        "end_masks": (*p.end_masks, end_mask),
        "event_masks": (*p.event_masks, event_mask),
        "t3_masks": (*p.t3_masks, t3),
        "names": names,
    }


def mentioned_branches(net: Network, e: A.SigExpr | None) -> set[int]:
    """The branches a property's atoms are about (their tasks, inputs, signals)."""
    if e is None:
        return set()
    p, split = net.program, net.split
    if isinstance(e, A.Fn) and e.fn == "pre":  # a signal, the instant before: that signal's
        return mentioned_branches(net, A.SigRef(e.arg, e.loc))
    if isinstance(e, A.Fn):
        names = [t.name for t in p.tasks]
        t = names.index(e.arg) if e.arg in names else -1
        return {b for b, tasks in enumerate(split.tasks) if t in tasks}
    if isinstance(e, A.SigRef):
        full = p.signal(e.name)
        if full in p.inputs:
            bit = 1 << p.inputs.index(full)
            return {b for b, ins in enumerate(split.inputs) if ins & bit}
        bit = 1 << p.internals.index(full)
        return {b for b, branch in enumerate(split.branches) if _emits(branch) & bit}
    if isinstance(e, A.Not):
        return mentioned_branches(net, e.item)
    return set().union(*(mentioned_branches(net, x) for x in e.items))


_RANK = {ERROR: 0, WARNING: 1, NOTE: 2}


def verify_network(
    net: Network, *, one_task_per_resource: bool = False, max_states: int = DEFAULT_MAX_STATES
) -> Report:
    """Every check of `verify`, on the products the module docstring describes. A product that
    does not compile (an instant with no reaction that the mission can reach) raises
    `MissionError` with the path, as `compile_program` does for a whole mission."""
    p = net.program
    groups: dict[tuple[int, ...], list[A.PropDecl]] = {(b,): [] for b in range(len(net.branches))}
    for prop in p.properties:
        members = tuple(sorted(mentioned_branches(net, prop.a) | mentioned_branches(net, prop.b))) or (0,)
        groups.setdefault(members, []).append(prop)
    checked: list[tuple[tuple[int, ...], Automaton, Report]] = []
    executed: set[int] = set()
    coverage: list[str] = []
    for members, props in groups.items():
        a = compile_program(product_program(net, members, tuple(props)), max_states)
        checked.append((members, a, verify(a, one_task_per_resource=one_task_per_resource, dead_code=False)))
        try:
            executed |= executed_sites(a)
        except CoverageError as e:
            coverage.append(str(e))
    results = _merge(net, checked)
    if coverage:
        results.append(CheckResult("dead code", False, f"not checked: {coverage[0]}", level=WARNING))
    else:
        results.append(dead_code_result(p, executed))
    warnings: list[str] = []
    for _, _, report in checked:
        warnings.extend(w for w in report.warnings if w not in warnings)
    states = sum(a.n_states for _, a, _ in checked)
    title = f"{net.describe()}; verified on {len(checked)} products ({states} states in all)"
    return Report(net.context, results, warnings[:5], title=title)


def _merge(net: Network, checked: list[tuple[tuple[int, ...], Automaton, Report]]) -> list[CheckResult]:
    """One result per check: the worst failure over the products (with its product's automaton
    for the counterexample), else the first product's summary."""
    by_name: dict[str, list[tuple[tuple[int, ...], Automaton, CheckResult]]] = {}
    for members, a, report in checked:
        for r in report.results:
            by_name.setdefault(r.name, []).append((members, a, r))
    out = []
    for name, found in by_name.items():
        failed = [x for x in found if not x[2].ok]
        if not failed:
            r = found[0][2]
            out.append(dataclasses.replace(r, summary=f"{r.summary}; in each of {len(found)} products"))
            continue
        members, a, r = min(failed, key=lambda x: _RANK[x[2].level])
        where = f"[in the product with {branch_names(net, members)}]"
        note = _stand_in_words(net, members, a, r)
        explanation = "\n".join(x for x in (r.explanation, note) if x)
        out.append(
            dataclasses.replace(r, summary=f"{r.summary} {where}", automaton=a, explanation=explanation)
        )
        del name
    return out


def _stand_in_words(net: Network, members: tuple[int, ...], a: Automaton, r: CheckResult) -> str:
    """What a counterexample's stand-in events mean, and the runs of the branches behind them: the
    product shows the stand-in's instants, not theirs (each needs its own inputs to get there)."""
    base = len(net.program.inputs)
    used = 0
    for step in r.counterexample or []:
        used |= step.inputs >> base
    if not used:
        return ""
    p = a.program
    lines = []
    for i in range(len(p.inputs) - base):
        if not used >> i & 1:
            continue
        name = p.inputs[base + i]
        what = name.rpartition(").")[2]
        branches = [b for b in range(len(net.branches)) if b not in members]  # what it stands for
        if what == "idle":
            meaning = "each of them has stopped for good (nothing runs, no input leads out)"
            runs = [(b, _shortest(net, b, _stuck_states(net.branches[b]))) for b in branches]
        elif what == "done":
            meaning = "each of them has ended"
            runs = [(b, _shortest(net, b, {net.branches[b].n_states - 1})) for b in branches]
        else:
            meaning = f"one of them {'enters the safe procedure' if what == 'safe' else 'exits its trap'}"
            if ".at_once." in name:
                meaning += " in its first instant"
            runs = []
        words = "; ".join(
            f"branch {b + 1} gets there after {_inputs_words(net, run)}" for b, run in runs if run is not None
        )
        lines.append(
            f"`{name}`: {meaning} — the stand-in for the branches outside this product, whose "
            f"instants are not theirs{': ' + words if words else ''}"
        )
    return "\n".join(lines)


def _stuck_states(a: Automaton) -> set[int]:
    return {s for loop in _fair_loops(a) if _stuck(a, loop) for s in loop}


def _shortest(net: Network, b: int, targets: set[int]) -> list[int] | None:
    """The shortest input sequence taking branch `b` from its start into `targets`."""
    a = net.branches[b]
    prev: dict[int, tuple[int, int]] = {0: (-1, 0)}
    queue = [0]
    for s in queue:
        if s in targets:
            out: list[int] = []
            while s:
                s, inputs = prev[s]
                out.append(inputs)
            return out[::-1]
        for inputs, (n, _) in a.table[s].items():
            if n not in prev:
                prev[n] = (s, inputs)
                queue.append(n)
    return None


def _inputs_words(net: Network, run: list[int]) -> str:
    """`{T1.done} ×34, then {Go}`: a branch's run, repeated instants counted."""
    if not run:
        return "its first instant"
    parts: list[tuple[int, int]] = []
    for inputs in run:
        if parts and parts[-1][0] == inputs:
            parts[-1] = (inputs, parts[-1][1] + 1)
        else:
            parts.append((inputs, 1))
    said = [net.program.describe_inputs(m) + (f" ×{k}" if k > 1 else "") for m, k in parts]
    return f"{len(run)} instants of its own: " + ", then ".join(said)
