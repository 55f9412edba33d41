"""The structural spin model: Promela written from the program's kernel terms, not from the table.

`promela/export.py` replays the compiled automaton, so spin re-checks the compiler's own output. This
model is built from the elaborated program (`Program.main`, `Program.safe`) by another route: one
process per parallel branch, code that follows the statements (`promela/terms.py`), and its own
account of signals and tasks. Where the two exports and the verifier agree, the compiler and the
semantics have been checked against each other.

Instants. Process `clock` loops: the environment picks the instant's inputs, the clock resumes
process `mission` (the main procedure, then the safe one), which resumes its children, and so on
down; each reacts until it pauses, terminates or exits, and reports. Then the clock checks the
instant and clears it. Every process's reaction is `atomic`: spin stores states at hand-overs only.

Environment (docs/mission-language.md): operator inputs in any combination; a Robot-Task raises
events only while active, at most one per instant; one resource's fault at most (`flt_R`) after
the first instant, while the mission runs and no task runs on the resource. Events a task's
statements cannot tell apart (same kind, in the same conditions: the five built-in T3s where
only `fatal` tests them) are one choice; an input or event no statement tests is not offered (it
changes no reaction).

Internal signals: the mission's semantics is logical correctness (one consistent status per
instant, checked by the compiler). The model guesses a signal's status when it is first tested in
an instant (`resolve_S`: present if already emitted, else either), and the clock drops, at the end
of the instant, every run whose guesses differ from what was emitted (`end_discard`). A compiled
mission has exactly one consistent status per instant, so one run survives: the reaction.

Tasks: `act_T` counts the active instances of T (two: a conflict), `nst_T` those started in this
instant (a task started and killed in the same instant was never started: no start, no stop),
`stp_T` is set when an instance stops.

Checks, after each instant, with the verifier's names (`ok_<check>`): safety (a type 3 event of an
active task enters the safe procedure, or ends it as failed, in that instant), conflicts (no two
active tasks claim the same resource or joints), the mission's `never` and `alternate` properties.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from orccadd.automaton.compiler.classes import EventClass, input_masks, task_classes
from orccadd.automaton.language import ast as A
from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.program import Program
from orccadd.automaton.promela.props import PROPERTIES, PropCode, check_properties, encode_properties
from orccadd.automaton.promela.spin import SETTINGS
from orccadd.automaton.promela.terms import Codegen
from orccadd.errors import OrccaddError

MAX_PROCESSES = 250  # spin's limit is 255, with the clock and the mission's process


class Names:
    """The model's variables for the program's inputs, events, tasks and internal signals."""

    def __init__(self, p: Program) -> None:
        self.p = p
        masks = sorted(input_masks(p))
        tested = 0
        for m in masks:
            tested |= m
        self.operators = [
            i for i in range(len(p.inputs)) if p.input_kind[i] == "operator" and tested >> i & 1
        ]
        # a resource's fault: offered after the first instant, while no task runs on the resource
        self.faults = [(r, bit.bit_length() - 1) for r, bit in p.fault_inputs if tested & bit]
        self.classes: list[list[EventClass]] = [task_classes(p, t, masks) for t in range(len(p.tasks))]
        pin, pint = K.pre_masks(p.main, p.safe)
        self.pre_inputs = [i for i in range(len(p.inputs)) if pin >> i & 1]
        self.pre_internals = [s for i, s in enumerate(p.internals) if pint >> i & 1]

    def task(self, t: int) -> str:
        return self.p.tasks[t].name

    def signal(self, bit: int) -> str:
        return f"em_{self.p.internals[bit.bit_length() - 1]}"

    def cond(self, c: K.Cond) -> str:
        op = c[0]
        if op == K.IN:
            return self._inputs(int(c[1]))
        if op == K.INT:
            names = [self.p.internals[i] for i in range(len(self.p.internals)) if c[1] >> i & 1]
            return "(" + " || ".join(f"gs_{n} == 1" for n in names) + ")"
        if op == K.PIN:
            return (
                "(" + " || ".join(f"pre_in{i} == 1" for i in range(len(self.p.inputs)) if c[1] >> i & 1) + ")"
            )
        if op == K.PINT:
            names = [self.p.internals[i] for i in range(len(self.p.internals)) if c[1] >> i & 1]
            return "(" + " || ".join(f"pre_{n} == 1" for n in names) + ")"
        if op == K.NOT:
            return f"!{self.cond(c[1])}"
        if op in (K.AND, K.OR):
            sep = " && " if op == K.AND else " || "
            return f"({self.cond(c[1])}{sep}{self.cond(c[2])})"
        return "1"

    def _inputs(self, mask: int) -> str:
        parts = [f"in_{self.p.inputs[i]}" for i in self.operators if mask >> i & 1]
        parts += [f"flt_{r}" for r, i in self.faults if mask >> i & 1]
        for t, classes in enumerate(self.classes):
            values = [c.value for c in classes if c.bits & mask]
            parts += [f"ev_{self.task(t)} == {v}" for v in values]
        return "(" + " || ".join(parts) + ")" if parts else "0"

    def resolve(self, c: K.Cond) -> list[str]:
        _, internal = K.cond_masks(c)
        return [f"resolve_{n}();" for i, n in enumerate(self.p.internals) if internal >> i & 1]

    def task_end(self, t: int) -> str:
        return self._inputs(self.p.end_masks[t])

    def prop_atom(self, e: A.SigRef | A.Fn) -> str:
        if isinstance(e, A.Fn):
            t = self.task([x.name for x in self.p.tasks].index(e.arg))
            return {"active": f"(act_{t} > 0)", "start": f"(nst_{t} > 0)", "stop": f"(stp_{t} == 1)"}[e.fn]
        name = self.p.signal(e.name)
        if name in self.p.internals:
            return f"(em_{name} == 1)"
        raise OrccaddError(
            f"it mentions the input {name}: the structural model offers inputs the program does not "
            "listen to, which the verifier does not count; export with `--model table`"
        )


def export_structure(
    p: Program, properties: tuple[str, ...] = PROPERTIES, extra: Callable[[Names], PropCode] | None = None
) -> str:
    """The structural Promela model of a program, with the requested checks (`PROPERTIES`) and any
    `extra` ones (declarations and end-of-instant checks written with the model's `Names`)."""
    check_properties(properties)
    names = Names(p)
    procs = Codegen(names, _ranks(p)).build(p.main, p.safe)
    if len(procs) > MAX_PROCESSES:
        raise OrccaddError(
            f"the structural Promela model needs {len(procs)} processes (spin allows {MAX_PROCESSES}): "
            "too many parallel branches; export with `--model table`"
        )
    props = encode_properties(p, names.prop_atom) if "properties" in properties else PropCode()
    if extra is not None:
        more = extra(names)
        props = PropCode(props.decls + more.decls, props.checks + more.checks, props.skipped + more.skipped)
    out = _header(p, props)
    out += _globals(p, names, [q.name for q in procs[1:]], props)
    out += _inlines(p)
    for q in procs:
        out += q.render()
    out += _clock(p, names, properties, props)
    return _dotted_names(p, "\n".join(out) + "\n")


def _dotted_names(p: Program, text: str) -> str:
    """A resource's input or output action (`arm.part_present`) is a plain signal here, named
    with `__` for the dot (a dot in Promela reads a struct field: task events use that)."""
    dotted = [n for n, k in zip(p.inputs, p.input_kind, strict=True) if k == "operator" and "." in n]
    dotted += [n for n in p.internals if "." in n]
    for name in sorted(dotted, key=len, reverse=True):
        flat = name.replace(".", "__")
        text = re.sub(rf"\b(in|em|gs|resolve|pre)_{re.escape(name)}\b", rf"\1_{flat}", text)
    return text


def _ranks(p: Program) -> dict[int, int]:
    codes: set[int] = set()
    stack: list[K.Term | None] = [p.main, p.safe]
    while stack:
        t = stack.pop()
        if isinstance(t, K.Exit):
            codes.add(t.code)
        stack.extend(K.children(t))
    return {code: 2 + i for i, code in enumerate(sorted(codes))}


def _header(p: Program, props: PropCode) -> list[str]:
    out = [
        f"/* mission {p.name} from {p.file}:",
        "   the structural model (orccadctl export-promela --model structure).",
        "   Written from the program's statements, not from the compiled table (promela/structure.py).",
        f"   Check with: {SETTINGS}",
    ]
    out += [f"   Not exported: {s}" for s in props.skipped]
    return [*out, "*/", ""]


def _globals(p: Program, names: Names, kids: list[str], props: PropCode) -> list[str]:
    out = ["byte cmd_mission;"]
    out += [f"byte cmd_{k}, res_{k};" for k in kids]
    out += [f"bit in_{p.inputs[i]};" for i in names.operators]
    out += [f"bit flt_{r};  /* {p.inputs[i]} */" for r, i in names.faults]
    if names.faults:
        out.append("bit started, over;  /* the first instant is over (no fault in it); the mission is */")
    for t, info in enumerate(p.tasks):
        events = ", ".join(
            f"{c.value} {c.name}{'…' if c.bits & (c.bits - 1) else ''}" for c in names.classes[t]
        )
        out.append(
            f"byte ev_{info.name}, act_{info.name}, nst_{info.name}; bit stp_{info.name};  /* {events} */"
        )
    out += [
        f"bit em_{s}; byte gs_{s};  /* emitted; guessed status 0 none, 1 present, 2 absent */"
        for s in p.internals
    ]
    out += [f"bit pre_in{i};  /* pre({p.inputs[i]}) */" for i in names.pre_inputs]
    out += [f"bit pre_{s};  /* pre({s}) */" for s in names.pre_internals]
    out += ["bit t3in, f_success, f_safe, f_failed, f_safe_done;", "bit ok_safety = 1, ok_conflicts = 1;"]
    return [*out, *props.decls, ""]


def _inlines(p: Program) -> list[str]:
    out = []
    for info in p.tasks:
        t = info.name
        out += [
            f"inline start_{t}() {{ act_{t}++; nst_{t}++ }}",
            f"inline stop_{t}() {{ act_{t}--; stp_{t} = 1 }}",
            f"inline kill_{t}() {{ if :: nst_{t} > 0 -> nst_{t}-- :: else -> stp_{t} = 1 fi; act_{t}-- }}",
        ]
    for s in p.internals:
        out.append(
            f"inline resolve_{s}() {{ if :: gs_{s} == 0 && em_{s} -> gs_{s} = 1 "
            f":: gs_{s} == 0 && !em_{s} -> if :: gs_{s} = 1 :: gs_{s} = 2 fi :: else -> skip fi }}"
        )
    return [*out, ""]


def _environment(p: Program, names: Names) -> list[str]:
    out = [f"if :: in_{p.inputs[i]} = 1 :: skip fi;" for i in names.operators]
    for t, classes in enumerate(names.classes):
        if not classes:
            continue
        name = p.tasks[t].name
        picks = " ".join(f":: ev_{name} = {c.value}{'; t3in = 1' if c.kind == 'T3' else ''}" for c in classes)
        out.append(f"if :: act_{name} > 0 -> if {picks} :: skip fi :: else -> skip fi;")
    faults = []  # one resource's fault at most per instant
    for r, _ in names.faults:
        idle = " && ".join(["1", *(f"act_{t.name} == 0" for t in p.tasks if t.resource == r)])
        faults.append(f":: {idle} -> flt_{r} = 1; t3in = 1")
    if faults:
        out.append(f"if :: started && !over -> if {' '.join(faults)} :: skip fi :: else -> skip fi;")
    return out


def _checks(p: Program, properties: tuple[str, ...], props: PropCode) -> list[str]:
    out = []
    if p.internals:
        wrong = " || ".join(f"(gs_{s} == 1 && !em_{s}) || (gs_{s} == 2 && em_{s})" for s in p.internals)
        out.append(f"if :: {wrong} -> goto end_discard :: else -> skip fi;  /* guessed statuses */")
    if "safety" in properties:
        out.append("ok_safety = (!t3in || f_safe || f_failed); assert(ok_safety); ok_safety = 1;")
    if "conflicts" in properties:
        claims = [f"act_{t.name} < 2" for t in p.tasks]
        for i, t1 in enumerate(p.tasks):
            claims += [
                f"!(act_{t1.name} > 0 && act_{t2.name} > 0)"
                for t2 in p.tasks[i + 1 :]
                if t1.claims_overlap(t2)
            ]
        out.append(f"ok_conflicts = ({' && '.join(claims) or '1'}); assert(ok_conflicts); ok_conflicts = 1;")
    return out + props.checks


def _clear(p: Program, names: Names) -> list[str]:
    """The end of an instant: what `pre(S)` will see in the next one, then every signal cleared."""
    out = [f"pre_in{i} = {names.cond((K.IN, 1 << i))};" for i in names.pre_inputs]
    out += [f"pre_{s} = em_{s};" for s in names.pre_internals]
    out += [f"in_{p.inputs[i]} = 0;" for i in names.operators]
    out += [f"flt_{r} = 0;" for r, _ in names.faults]
    out += ["started = 1; over = over || f_success || f_failed || f_safe_done;"] if names.faults else []
    out += [f"ev_{t.name} = 0; nst_{t.name} = 0; stp_{t.name} = 0;" for t in p.tasks]
    out += [f"em_{s} = 0; gs_{s} = 0;" for s in p.internals]
    return [*out, "t3in = 0; f_success = 0; f_safe = 0; f_failed = 0; f_safe_done = 0"]


def _clock(p: Program, names: Names, properties: tuple[str, ...], props: PropCode) -> list[str]:
    body = [
        "/* the environment: this instant's inputs */",
        *_environment(p, names),
        "cmd_mission = 2; (cmd_mission == 0);  /* the instant */",
        *_checks(p, properties, props),
        *_clear(p, names),
    ]
    return [
        "active proctype clock() {",
        "  atomic {",
        "    do",
        "    :: " + "\n       ".join(body),
        "    od;",
        "  end_discard:  /* the guessed statuses of internal signals were not the emitted ones */",
        "    false",
        "  }",
        "}",
    ]
