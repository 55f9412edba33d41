"""Both routes in one spin model: the structural model and the compiled table, in lockstep.

The clock of the structural model (`promela/structure.py`) also steps the table: after each instant
it looks up the table's transition for the inputs the environment gave (each class's first event,
masked by the state's relevant inputs as the runtime does) and asserts that the table's actions and
next active tasks are the model's own (`ok_lockstep`, check "lockstep"). spin explores every input
sequence, so the assertion holds if and only if the compiler and the structural semantics react
alike in every reachable instant: a far finer cross-check than comparing verdicts.
"""

from __future__ import annotations

from orccadd.automaton.compiler.automaton import Automaton
from orccadd.automaton.promela.props import PROPERTIES, PropCode
from orccadd.automaton.promela.structure import Names, export_structure


def export_lockstep(a: Automaton, properties: tuple[str, ...] = PROPERTIES) -> str:
    return export_structure(a.program, properties, extra=lambda names: _lockstep(a, names))


def _lockstep(a: Automaton, names: Names) -> PropCode:
    checks = ["if  /* the table's transition for this instant's inputs */"]
    for s in range(a.n_states):
        checks += [f":: tstate == {s} ->", "   if"]
        for key, (n, actions) in sorted(a.table[s].items()):
            guard = _guard(a, names, s, key)
            if guard is not None:
                checks.append(f"   :: {guard} -> tstate = {n}; ok_lockstep = {_same(a, n, actions)}")
        checks += ["   :: else -> ok_lockstep = 0", "   fi"]
    checks += ["fi;", "assert(ok_lockstep); ok_lockstep = 1;"]
    return PropCode(["int tstate = 0;  /* the compiled automaton's state */", "bit ok_lockstep = 1;"], checks)


def _guard(a: Automaton, names: Names, s: int, key: int) -> str | None:
    """The environment's choices that give this row's inputs; None: a row for an event that is not
    the first of its class (the model offers each class once)."""
    p, rel = a.program, a.relevant[s]
    parts = [f"in_{p.inputs[i]} == {key >> i & 1}" for i in names.operators if rel >> i & 1]
    parts += [f"flt_{r} == {key >> i & 1}" for r, i in names.faults if rel >> i & 1]
    for t in sorted(set(a.active[s])):
        ev, classes = f"ev_{p.tasks[t].name}", names.classes[t]
        bit = key & p.event_masks[t]
        if bit:
            chosen = [c.value for c in classes if c.rep == bit]
            if not chosen:
                return None
            parts.append(f"{ev} == {chosen[0]}")
        else:
            quiet = [0, *(c.value for c in classes if not c.rep & rel)]
            parts.append("(" + " || ".join(f"{ev} == {v}" for v in quiet) + ")")
    return " && ".join(parts) or "1"


def _same(a: Automaton, n: int, actions: int) -> str:
    p = a.program
    starts, stops = a.starts(actions), a.stops(actions)
    parts = []
    for t, info in enumerate(p.tasks):
        name = info.name
        parts += [
            f"(nst_{name} > 0) == {starts >> t & 1}",
            f"stp_{name} == {stops >> t & 1}",
            f"act_{name} == {a.active[n].count(t)}",
        ]
    parts += [f"em_{sig} == {actions >> (a.emit_base + k) & 1}" for k, sig in enumerate(p.internals)]
    flags = (("f_success", a.success_bit), ("f_safe", a.safe_bit), ("f_failed", a.failed_bit),
             ("f_safe_done", a.safe_done_bit))  # fmt: skip
    parts += [f"{f} == {int(bool(actions & bit))}" for f, bit in flags]
    return "(" + " && ".join(parts) + ")"
