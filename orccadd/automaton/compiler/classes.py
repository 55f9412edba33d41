"""A task's events grouped by what the program can tell of them.

Two events of one task that are of the same kind and held by the same input masks the program
tests (its conditions, what ends each task) give the same reaction in every state: the program
cannot tell them apart. The compiler explores one event per class (its first, the class's
representative) and the runtime maps the others to it (`Automaton.event_rep`): a task's built-in
type 3 exceptions, caught together by the procedure's `on fatal`, are one class, not six. The
structural Promela model offers each class once, for the same reason.
"""

from __future__ import annotations

from dataclasses import dataclass

from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.program import Program


@dataclass(frozen=True)
class EventClass:
    task: int
    value: int  # ev_T == value in the instants the task raises it
    kind: str
    bits: int  # every input bit of the class
    rep: int  # the input bit of its first event, the one the environment raises
    name: str  # the first event's full name


def input_masks(p: Program) -> set[int]:
    """Every input mask a statement tests (conditions, and what ends each task)."""
    out = set(p.end_masks)
    stack: list[K.Term | None] = [p.main, p.safe]
    while stack:
        t = stack.pop()
        for c in K.conds(t):
            _cond_in_masks(c, out)
        stack.extend(K.children(t))
    return out


def _cond_in_masks(c: K.Cond, out: set[int]) -> None:
    if c[0] in (K.IN, K.PIN):
        out.add(int(c[1]))
    elif c[0] in (K.AND, K.OR, K.NOT):
        for sub in c[1:]:
            _cond_in_masks(sub, out)


def task_classes(p: Program, t: int, masks: list[int]) -> list[EventClass]:
    """A task's events grouped by what the program can tell of them (kind, the masks holding them);
    an event in no mask changes no reaction and is left out."""
    groups: dict[tuple[str, tuple[bool, ...]], list[tuple[str, int]]] = {}
    for kind, name, bit in p.tasks[t].events:
        where = tuple(bool(m & bit) for m in masks)
        if any(where):
            groups.setdefault((kind, where), []).append((name, bit))
    out = []
    for value, ((kind, _), events) in enumerate(groups.items(), start=1):
        bits = 0
        for _, b in events:
            bits |= b
        out.append(EventClass(t, value, kind, bits, events[0][1], events[0][0]))
    return out


def event_classes(p: Program) -> list[list[EventClass]]:
    """Every task's event classes (see the module docstring), tasks in program order."""
    masks = sorted(input_masks(p))
    return [task_classes(p, t, masks) for t in range(len(p.tasks))]


def event_reps(p: Program, classes: list[list[EventClass]]) -> tuple[int, ...]:
    """Per input index, the input bit that stands for it: its class's representative (an
    operator input, or an event in no class, stands for itself)."""
    rep = [1 << i for i in range(len(p.inputs))]
    for task in classes:
        for c in task:
            bits = c.bits
            while bits:
                low = bits & -bits
                rep[low.bit_length() - 1] = c.rep
                bits ^= low
    return tuple(rep)
