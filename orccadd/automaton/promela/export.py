"""Export a mission to Promela, so that spin can cross-check the verifier's verdicts.

Two models (`export_model`, `orccadctl export-promela --model ...`):

- `structure` (the default, `promela/structure.py`): written from the program's statements, a
  process per parallel branch; spin then checks the compiler and the semantics against each other;
- `lockstep` (`promela/lockstep.py`): both in one model, spin asserts they react alike;
- `table` (`export_promela` below): replays the compiled automaton's table, keeping its own account
  of which Robot-Tasks are active (from the start/stop actions of each transition) and applying the
  environment model itself: a transition whose inputs hold events of a task spin believes inactive
  is not taken.

Both assert, after each instant, with the verifier's check names (`ok_<check>`, see
`promela/spin.py`): safety (an instant holding a type 3 exception of an active task, or a
resource's fault, enters the safe procedure, or ends it failed), conflicts (no two active tasks
claim the same resource or joints), and the mission's `never` and `alternate` properties (`promela/props.py`).
"""

from __future__ import annotations

from orccadd.automaton.compiler.automaton import Automaton
from orccadd.automaton.language import ast as A
from orccadd.automaton.promela.props import PROPERTIES, check_properties, encode_properties
from orccadd.automaton.promela.spin import SETTINGS, SpinVerdict, run_spin
from orccadd.errors import OrccaddError

__all__ = ["MODELS", "PROPERTIES", "SpinVerdict", "export_model", "export_promela", "run_spin"]

MODELS = ("structure", "table", "lockstep")
MAX_TASKS = 30  # the table model keeps the active tasks as the bits of one int


def export_model(a: Automaton, model: str = "structure", properties: tuple[str, ...] = PROPERTIES) -> str:
    if model == "structure":
        from orccadd.automaton.promela.structure import export_structure

        return export_structure(a.program, properties)
    if model == "table":
        return export_promela(a, properties)
    if model == "lockstep":
        from orccadd.automaton.promela.lockstep import export_lockstep

        return export_lockstep(a, properties)
    raise OrccaddError(f"unknown model {model!r} (choose from {', '.join(MODELS)})")


def export_promela(a: Automaton, properties: tuple[str, ...] = PROPERTIES) -> str:
    """The table-replay model."""
    p = a.program
    check_properties(properties)
    if len(p.tasks) > MAX_TASKS:
        raise OrccaddError(
            f"the table's Promela model handles up to {MAX_TASKS} tasks (this mission has {len(p.tasks)})"
        )
    atoms = _Atoms(a)
    props = encode_properties(p, atoms.atom) if "properties" in properties else None
    out = [
        f"/* mission {p.name} from {p.file}: {a.n_states} states, {a.n_transitions} transitions.",
        "   The table-replay model (orccadctl export-promela --model table).",
        f"   Check with: {SETTINGS}",
        *(f"   Not exported: {s}" for s in (props.skipped if props else [])),
        "*/",
        "",
        "int state = 0;",
        "int act = 0;  /* bit t: task t is active, as spin sees it */",
        "int evsrc; int t3src; bit fltsrc; int starts; int stops; bool handled; int emits;",
        *(f"bit {atoms.var(n)};" for n in atoms.inputs),
        "bit ok_safety = 1, ok_conflicts = 1;",
        *(props.decls if props else []),
        "",
        "active proctype mission() {",
        "  do",
        "  :: atomic {",
        "     if",
    ]
    for s in range(a.n_states):
        out += _state(a, s, atoms)
    out += ["     fi;", "     act = (act & ~stops) | starts;"]
    out += ["     " + c for c in _checks(a, properties)]
    out += ["     " + c for c in (props.checks if props else [])]
    clear = "".join(f"; {atoms.var(n)} = 0" for n in atoms.inputs)
    out += [
        f"     evsrc = 0; t3src = 0; fltsrc = 0; starts = 0; stops = 0; handled = 0; emits = 0{clear}",
        "  }",
        "  od",
        "}",
        "",
    ]
    return "\n".join(out)


class _Atoms:
    """How the properties' atoms read in the table model."""

    def __init__(self, a: Automaton) -> None:
        self.a = a
        self.inputs: list[str] = []  # the inputs a property mentions (each a bit of the model)
        for prop in a.program.properties:
            for e in (prop.a, prop.b):
                self._collect(e)
        if len(a.program.internals) > 31:
            raise OrccaddError("the table's Promela model handles up to 31 internal signals")

    def _collect(self, e: A.SigExpr | None) -> None:
        if isinstance(e, A.SigRef):
            name = self.a.program.signal(e.name)
            if name in self.a.program.inputs and name not in self.inputs:
                self.inputs.append(name)
        elif isinstance(e, A.Not):
            self._collect(e.item)
        elif isinstance(e, A.And | A.Or):
            for i in e.items:
                self._collect(i)

    def var(self, name: str) -> str:
        return "in_" + "".join(c if c.isalnum() else "_" for c in name) + f"_{self.inputs.index(name)}"

    def atom(self, e: A.SigRef | A.Fn) -> str:
        p = self.a.program
        if isinstance(e, A.Fn):
            t = [x.name for x in p.tasks].index(e.arg)
            word = {"active": "act", "start": "starts", "stop": "stops"}[e.fn]
            return f"((({word}) >> {t}) & 1)"
        name = p.signal(e.name)
        if name in p.inputs:
            return self.var(name)
        return f"((emits >> {p.internals.index(name)}) & 1)"


def _state(a: Automaton, s: int, atoms: _Atoms) -> list[str]:
    p = a.program
    out = [f"     :: state == {s} ->", "        if"]
    alternatives: list[str] = []
    emit_mask = (1 << len(p.internals)) - 1
    for inputs, (n, actions) in sorted(a.table[s].items()):
        ev = t3 = 0
        for i in range(len(p.inputs)):
            if inputs >> i & 1 and p.input_task[i] >= 0:
                ev |= 1 << p.input_task[i]
                if p.input_kind[i] == "T3":
                    t3 |= 1 << p.input_task[i]
        handled = int(bool(actions & (a.safe_bit | a.failed_bit)))
        idle = 0  # a resource's fault: only while spin sees no task active on it
        for r, bit in p.fault_inputs:
            if inputs & bit:
                idle |= sum(1 << t for t, info in enumerate(p.tasks) if info.resource == r)
        ins = "".join(f"{atoms.var(name)} = {inputs >> p.inputs.index(name) & 1}; " for name in atoms.inputs)
        alt = (
            f"        :: ({ev} & ~act) == 0 && ({idle} & act) == 0 -> evsrc = {ev}; t3src = {t3}; "
            f"fltsrc = {int(bool(inputs & p.fault_mask))}; "
            f"stops = {a.stops(actions)}; starts = {a.starts(actions)}; handled = {handled}; "
            f"emits = {(actions >> a.emit_base) & emit_mask}; {ins}state = {n}"
        )
        if alt not in alternatives:
            alternatives.append(alt)
    return [*out, *alternatives, "        fi"]


def _checks(a: Automaton, properties: tuple[str, ...]) -> list[str]:
    p = a.program
    out = []
    if "safety" in properties:
        out.append("ok_safety = ((t3src == 0 && !fltsrc) || handled); assert(ok_safety); ok_safety = 1;")
    if "conflicts" in properties:
        pairs = [
            f"!((act >> {i}) & 1 && (act >> {j}) & 1)"
            for i, t1 in enumerate(p.tasks)
            for j in range(i + 1, len(p.tasks))
            if t1.claims_overlap(p.tasks[j])
        ]
        out.append(f"ok_conflicts = ({' && '.join(pairs) or '1'}); assert(ok_conflicts); ok_conflicts = 1;")
    return out
