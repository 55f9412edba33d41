"""Abstract views of a compiled mission: projection on chosen signals, then minimisation by weak
bisimulation (partition refinement), as in the seed's figure 6; rendering with Graphviz.

A transition's label is the set of chosen atoms it shows: an input only where it changed the
reaction (the same instant without it would have gone elsewhere), `start(T)`/`stop(T)` actions,
emitted signals, `success`, `safe`. A label with no chosen atom is silent (τ). By default the view
leaves out type 3 exceptions (their handling is what the safety check proves); `faults=True` keeps them.

In the picture a state shows its number and the Robot-Tasks active in it; states with the same
tasks active are drawn in one box (a cluster: one step of a sequence, or one combination of
parallel branches), the safe procedure's in red, final states doubled. The full view labels each
edge with the inputs it needs (`Home.done`; none: it is taken otherwise) and its actions.
"""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from orccadd.automaton.compiler.automaton import END, MAIN, SAFE, Automaton
from orccadd.automaton.compiler.network import Network
from orccadd.automaton.language import kernel as K
from orccadd.errors import OrccaddError

TAU = ""
EDGE_ALTERNATIVES_SHOWN = 4  # input sets named on one edge of the full view
TYPE_3 = "type 3"  # the label of the summed-up exception edges of a full view without `--faults`


@dataclass(frozen=True)
class Lts:
    """A labelled transition system; label "" is τ. States 0..n-1, `initial` the start."""

    n: int
    initial: int
    edges: tuple[tuple[int, str, int], ...]
    names: tuple[str, ...]  # per state, for the picture
    tasks: tuple[str, ...] = ()  # per state: the Robot-Tasks active, for the picture
    phases: tuple[int, ...] = ()  # per state: MAIN, SAFE or END

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
    return Lts(a.n_states, 0, tuple(sorted(edges)), a.where, _tasks(a), a.phase)


def _tasks(a: Automaton) -> tuple[str, ...]:
    names = [t.name for t in a.program.tasks]
    return tuple(", ".join(names[i] for i in act) for act in a.active)


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
    rep = [-1] * len(order)  # a state of each block (the first): its names, tasks and phase
    for s in range(lts.n):
        b = block[s]
        if b in order and rep[order[b]] < 0:
            rep[order[b]] = s
    return Lts(
        len(order),
        0,
        edges,
        tuple(lts.names[s] for s in rep),
        tuple(lts.tasks[s] for s in rep) if lts.tasks else (),
        tuple(lts.phases[s] for s in rep) if lts.phases else (),
    )


def _tau_closure(s: int, succ_tau: list[list[int]]) -> set[int]:
    seen, stack = {s}, [s]
    while stack:
        for t in succ_tau[stack.pop()]:
            if t not in seen:
                seen.add(t)
                stack.append(t)
    return seen


def full_view(a: Automaton, *, faults: bool = False) -> Lts:
    """The whole automaton, one edge per (source, actions, target), labelled `inputs / actions`:
    the least sets of inputs that take it, `∨` between them (none: it is taken otherwise)."""
    p = a.program
    t3_bits = 0
    for m in p.t3_masks:
        t3_bits |= m
    groups: dict[tuple[int, int, int], list[int]] = {}  # (source, target, actions) → input sets
    to_safe: set[tuple[int, str, int]] = set()  # without `faults`: one edge per (source, target)
    for s in range(a.n_states):
        for inputs, (n, actions) in a.table[s].items():
            if inputs & t3_bits and not faults:
                if n != s:  # (else drawn nowhere: the safe procedure would look unreachable)
                    to_safe.add((s, TYPE_3, n))
                continue
            if n == s and not actions:
                continue
            groups.setdefault((s, n, actions), []).extend(a.stands_for(inputs))
    edges = set()
    for (s, n, actions), sets in groups.items():
        least = [x for x in sets if not any(y != x and y & x == y for y in sets)]
        alternatives = [" ∧ ".join(p.inputs[i] for i in range(len(p.inputs)) if x >> i & 1) for x in least]
        label = "" if 0 in least else " ∨ ".join(sorted(alternatives)[:EDGE_ALTERNATIVES_SHOWN])
        if len(least) > EDGE_ALTERNATIVES_SHOWN and label:
            label += " ∨ …"
        acts = ", ".join(a.describe_actions(actions))
        edges.add((s, f"{label} / {acts}" if label and acts else label or acts, n))
    edges |= {e for e in to_safe if not any(x[0] == e[0] and x[2] == e[2] for x in edges)}
    return Lts(a.n_states, 0, tuple(sorted(edges)), a.where, _tasks(a), a.phase)


_DOT_HEAD = (
    "  rankdir=LR;",
    '  node [shape=circle, fontname="Helvetica"];',
    '  edge [fontname="Helvetica", fontsize=10];',
)


def to_dot(lts: Lts, title: str) -> str:
    """Graphviz text: a state's number and active tasks; a box per set of active tasks."""
    return "\n".join([f'digraph "{_q(title)}" {{', *_DOT_HEAD, *_graph(lts, "s"), "}"]) + "\n"


def network_views(net: Network, *, faults: bool = False) -> list[tuple[str, Lts]]:
    """The full view of a network's context (its edges say the par's code: `par done`, ...)
    and of each branch (their codes left out: a branch's `ended` state says it)."""
    p, ctx = net.program, net.context
    n_in = len(p.inputs)
    real = (1 << n_in) - 1
    code_names = tuple(
        "par done" if c == K.DONE else "par paused" if c == K.PAUSED else f"par exits ({c})"
        for c in net.codes
    )
    table = [
        {
            (key & real) | (1 << (n_in + (key >> n_in)) if net.hole_present[s] else 0): hit
            for key, hit in row.items()
        }
        for s, row in enumerate(ctx.table)
    ]
    shown = dataclasses.replace(p, inputs=(*p.inputs, *code_names))
    context = dataclasses.replace(ctx, program=shown, table=tuple(table))
    low = (1 << net.code_shift) - 1
    parts = [("context", full_view(context, faults=faults))]
    for b, a in enumerate(net.branches):
        rows = tuple({k: (j, act & low) for k, (j, act) in row.items()} for row in a.table)
        name = f"branch {b + 1} of the par at line {net.split.loc.line}"
        parts.append((name, full_view(dataclasses.replace(a, table=rows), faults=faults)))
    return parts


def to_dot_network(parts: list[tuple[str, Lts]], title: str) -> str:
    """A network (compiler/network.py): each component's graph in a box of its own (the context's, then
    each branch's), drawn as `to_dot` draws one automaton."""
    out = [f'digraph "{_q(title)}" {{', *_DOT_HEAD]
    for k, (name, lts) in enumerate(parts):
        out.append(f'  subgraph cluster_part{k} {{ label="{_q(name)}"; style=bold;')
        out.extend("  " + line for line in _graph(lts, f"p{k}_"))
        out.append("  }")
    return "\n".join([*out, "}"]) + "\n"


def _graph(lts: Lts, prefix: str) -> list[str]:
    out = [f"  {prefix}start [shape=point];"]
    boxes: dict[str, list[int]] = {}
    for s in range(lts.n):
        boxes.setdefault(lts.tasks[s] if lts.tasks else "", []).append(s)
    for k, (tasks, states) in enumerate(boxes.items()):
        if tasks:
            out.append(f'  subgraph cluster_{prefix}{k} {{ label="{_q(tasks)}"; style=rounded; color=grey;')
        for s in states:
            out.append("    " + _node(lts, s, prefix))
        if tasks:
            out.append("  }")
    out.append(f"  {prefix}start -> {prefix}{lts.initial};")
    for s, lab, t in lts.edges:
        style = ' style=dashed label="τ"' if lab == TAU else f' label="{_q(lab)}"'
        if lab == TYPE_3:  # the exceptions, summed up (`graph --faults` draws each)
            style = f' style=dashed color=red fontcolor=red label="{TYPE_3}"'
        out.append(f"  {prefix}{s} -> {prefix}{t} [{style.strip()}];")
    return out


def _node(lts: Lts, s: int, prefix: str) -> str:
    phase = lts.phases[s] if lts.phases else MAIN
    tasks = lts.tasks[s] if lts.tasks else ""
    label = f"{s}\\n{_q(tasks)}" if tasks else str(s)
    shape = ", shape=doublecircle" if phase == END else ""
    colour = ", color=red, fontcolor=red" if phase == SAFE else ""
    return f'{prefix}{s} [label="{label}", tooltip="{_q(lts.names[s])}"{shape}{colour}];'


def _q(text: str) -> str:
    """Text inside a DOT string."""
    return text.replace("\\", "\\\\").replace('"', "'")


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
