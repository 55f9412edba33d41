"""Abstract views of a compiled mission: projection on chosen signals, then minimisation by weak
bisimulation (partition refinement), as in the seed's figure 6; rendering with Graphviz.

A transition's label is the set of chosen atoms it shows: an input only where it changed the
reaction (the same instant without it would have gone elsewhere), `start(T)`/`stop(T)` actions,
emitted signals, `success`, `safe`. A label with no chosen atom is silent (τ). By default the view
leaves out type 3 exceptions (their handling is what the safety check proves); `faults=True` keeps them.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from orccadd.automaton.automaton import Automaton
from orccadd.errors import OrccaddError

TAU = ""


@dataclass(frozen=True)
class Lts:
    """A labelled transition system; label "" is τ. States 0..n-1, `initial` the start."""

    n: int
    initial: int
    edges: tuple[tuple[int, str, int], ...]
    names: tuple[str, ...]  # per state, for the picture

    def visible_labels(self) -> set[str]:
        return {lab for _, lab, _ in self.edges if lab != TAU}


@dataclass(frozen=True)
class _Atom:
    display: str
    kind: str  # "input", "action"
    bit: int


def resolve_atoms(a: Automaton, names: Iterable[str]) -> list[_Atom]:
    """User names → atoms. A task name alone means its activation, start(T)."""
    p = a.program
    tasks = [t.name for t in p.tasks]
    out: list[_Atom] = []
    for raw in names:
        n = raw.strip()
        if not n:
            continue
        if n in tasks:
            n = f"start({n})"
        if n.endswith(")") and "(" in n:
            fn, arg = n[:-1].split("(", 1)
            if fn not in ("start", "stop") or arg not in tasks:
                raise OrccaddError(
                    f"{raw!r}: expected start(TASK) or stop(TASK) with TASK one of {', '.join(tasks)}"
                )
            base = a.start_base if fn == "start" else a.stop_base
            out.append(_Atom(n, "action", 1 << (base + tasks.index(arg))))
        elif n in ("success", "safe", "failed"):
            bit = {"success": a.success_bit, "safe": a.safe_bit, "failed": a.failed_bit}[n]
            out.append(_Atom(n, "action", bit))
        elif n in p.internals:
            out.append(_Atom(n, "action", 1 << (a.emit_base + p.internals.index(n))))
        else:
            out.append(_Atom(n, "input", 1 << p.inputs.index(p.signal(n))))
    return out


def project(a: Automaton, names: Iterable[str], *, faults: bool = False) -> Lts:
    """The automaton seen through the chosen atoms only (reachable part)."""
    atoms = resolve_atoms(a, names)
    p = a.program
    t3_bits = 0
    for m in p.t3_masks:
        t3_bits |= m
    edges: set[tuple[int, str, int]] = set()
    seen, stack = {0}, [0]
    while stack:
        s = stack.pop()
        row = a.table[s]
        for inputs, (n, actions) in row.items():
            if inputs & t3_bits and not faults:
                continue
            shown = []
            for at in atoms:
                if at.kind == "action":
                    if actions & at.bit:
                        shown.append(at.display)
                elif inputs & at.bit and row.get(inputs & ~at.bit) != (n, actions):
                    shown.append(at.display)
            edges.add((s, ", ".join(shown), n))
            if n not in seen:
                seen.add(n)
                stack.append(n)
    return Lts(a.n_states, 0, tuple(sorted(edges)), a.where)


def minimize(lts: Lts) -> Lts:
    """Quotient by weak bisimulation (τ steps unobservable), reachable part, states renumbered."""
    succ_tau: list[list[int]] = [[] for _ in range(lts.n)]
    visible: list[list[tuple[str, int]]] = [[] for _ in range(lts.n)]
    for s, lab, t in lts.edges:
        (succ_tau[s].append(t) if lab == TAU else visible[s].append((lab, t)))
    closure = [_tau_closure(s, succ_tau) for s in range(lts.n)]
    weak: list[set[tuple[str, int]]] = []
    for s in range(lts.n):
        w: set[tuple[str, int]] = {(TAU, v) for v in closure[s]}
        for mid in closure[s]:
            for lab, u in visible[mid]:
                w.update((lab, v) for v in closure[u])
        weak.append(w)
    block = [0] * lts.n
    count = 1
    while True:
        sigs = [(block[s], frozenset((lab, block[v]) for lab, v in weak[s])) for s in range(lts.n)]
        ids: dict[object, int] = {}
        new = [ids.setdefault(sig, len(ids)) for sig in sigs]
        if len(ids) == count:
            break
        block, count = new, len(ids)
    # renumber reachable blocks breadth first from the initial one
    q_edges = {
        (block[s], lab, block[t]) for s, lab, t in lts.edges if not (lab == TAU and block[s] == block[t])
    }
    order = {block[lts.initial]: 0}
    frontier = [block[lts.initial]]
    while frontier:
        b = frontier.pop(0)
        for s, _, t in sorted(q_edges):
            if s == b and t not in order:
                order[t] = len(order)
                frontier.append(t)
    edges = tuple(sorted({(order[s], lab, order[t]) for s, lab, t in q_edges if s in order}))
    names = [""] * len(order)
    for s in range(lts.n):
        b = block[s]
        if b in order and not names[order[b]]:
            names[order[b]] = lts.names[s]
    return Lts(len(order), 0, edges, tuple(names))


def _tau_closure(s: int, succ_tau: list[list[int]]) -> set[int]:
    seen, stack = {s}, [s]
    while stack:
        for t in succ_tau[stack.pop()]:
            if t not in seen:
                seen.add(t)
                stack.append(t)
    return seen


def full_view(a: Automaton, *, faults: bool = False) -> Lts:
    """The whole automaton, one edge per (source, actions, target), labelled with its actions."""
    p = a.program
    t3_bits = 0
    for m in p.t3_masks:
        t3_bits |= m
    edges: set[tuple[int, str, int]] = set()
    for s in range(a.n_states):
        for inputs, (n, actions) in a.table[s].items():
            if inputs & t3_bits and not faults:
                continue
            if n == s and not actions:
                continue
            edges.add((s, ", ".join(a.describe_actions(actions)), n))
    return Lts(a.n_states, 0, tuple(sorted(edges)), a.where)


def to_dot(lts: Lts, title: str) -> str:
    out = [f'digraph "{title}" {{', "  rankdir=LR;", '  node [shape=circle, fontname="Helvetica"];',
           '  edge [fontname="Helvetica", fontsize=10];', '  start [shape=point];']  # fmt: skip
    for s in range(lts.n):
        tip = lts.names[s].replace('"', "'")
        out.append(f'  s{s} [label="{s}", tooltip="{tip}"];')
    out.append(f"  start -> s{lts.initial};")
    for s, lab, t in lts.edges:
        style = ' style=dashed label="τ"' if lab == TAU else f' label="{lab}"'
        out.append(f"  s{s} -> s{t} [{style.strip()}];")
    out.append("}")
    return "\n".join(out) + "\n"


def render(dot_text: str, out: Path) -> None:
    """Write DOT text, or render it to .svg/.png/.pdf with Graphviz's `dot`."""
    fmt = out.suffix.lstrip(".").lower()
    if fmt == "dot":
        out.write_text(dot_text)
        return
    if fmt not in ("svg", "png", "pdf"):
        raise OrccaddError(f"{out}: unknown picture format {fmt!r} (use .svg, .png, .pdf or .dot)")
    exe = shutil.which("dot")
    if exe is None:
        raise OrccaddError("Graphviz `dot` is not installed (make setup installs it; or write a .dot file)")
    proc = subprocess.run(
        [exe, f"-T{fmt}", "-o", str(out)], input=dot_text, text=True, capture_output=True, timeout=60
    )
    if proc.returncode != 0:
        raise OrccaddError(f"dot failed: {proc.stderr.strip()}")
