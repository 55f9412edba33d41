"""A checked mission: its signals, Robot-Task signatures and kernel terms (input of the compiler)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from orccadd.automaton.language.ast import Loc, MissionAst, PropDecl, SigExpr
from orccadd.automaton.language.kernel import Term
from orccadd.errors import OrccaddError

# Event kinds of a Robot-Task as the mission sees them, in input-bit order within a task.
EVENT_KINDS = ("post", "pre", "T2", "T3", "sync")
# Runtime priority when one task reports several events in one tick (the environment model of the
# verifier: one event per task per instant, the most severe kept).
PRIORITY = {"T3": 0, "T2": 1, "post": 2, "pre": 3, "sync": 4}
BUILTIN_T2 = ("PreconditionTimeout",)


def event_full_name(task: str, kind: str, name: str) -> str:
    if kind == "post":
        return f"{task}.done"
    if kind == "pre":
        return f"{task}.pre"
    return f"{task}.{kind}.{name}"


@dataclass(frozen=True)
class TaskInfo:
    """A Robot-Task's signature: what it claims and which events it may raise."""

    index: int
    name: str
    resource: str
    joints: tuple[str, ...]  # empty: the whole resource
    source: str
    loc: Loc
    events: tuple[tuple[str, str, int], ...]  # (kind, full name, input bit)
    # drives its resource while active (False: a network's stand-in for branches that run no task)
    runs: bool = True

    def mask(self, *kinds: str) -> int:
        m = 0
        for kind, _, bit in self.events:
            if kind in kinds:
                m |= bit
        return m

    def claims_overlap(self, other: TaskInfo) -> bool:
        if self.resource != other.resource:
            return False
        if not self.joints or not other.joints:
            return True
        return bool(set(self.joints) & set(other.joints))


@dataclass(frozen=True, eq=False)
class Site:
    """A statement the dead-code check follows (`verify`): a task activation, an `emit`, or the
    start of a branch (a `present`'s `then`/`else`, a handler, the body of `when`/`every`, the safe
    procedure). `term` is the kernel term that starts it, found by identity in `Program.main` or
    `Program.safe`; a procedure called twice has two sites at one place."""

    kind: str  # "task", "emit", "branch" or "safe" (the safe procedure)
    what: str  # how a report names it: "task Grip", "`emit Ready`", "the `else` of `present Go`"
    loc: Loc
    term: Term
    parent: int  # the enclosing site's index in `Program.sites`, -1 for none


@dataclass(frozen=True)
class Program:
    """Everything the compiler, the verifier and the interpreter need, all names resolved."""

    name: str
    file: str
    text: str
    # input bit i ↔ inputs[i]: operator inputs first, then the resources' faults, then task events
    inputs: tuple[str, ...]
    input_task: tuple[int, ...]  # per input bit: the task raising it, -1 for an operator input or a fault
    input_kind: tuple[str, ...]  # per input bit: "operator", "fault" or an EVENT_KINDS entry
    internals: tuple[str, ...]  # internal signal bit i ↔ internals[i]
    tasks: tuple[TaskInfo, ...]
    operator_mask: int
    end_masks: tuple[int, ...]  # per task: post | T2 | T3 (what ends `run T`)
    event_masks: tuple[int, ...]  # per task: every event it can raise
    t3_masks: tuple[int, ...]
    main: Term
    safe: Term  # the safe procedure, wrapped so that a type 3 inside it ends the mission (failed)
    properties: tuple[PropDecl, ...]
    ast: MissionAst
    names: Mapping[str, tuple[str, ...]]  # every accepted spelling (full or short) -> full names
    sites: tuple[Site, ...] = ()  # what the dead-code check follows
    # per declared resource: (its name, the input bit of `R.fault`: the resource safe-stopped while
    # no task of the mission runs on it; a fault while one runs is that task's type 3)
    fault_inputs: tuple[tuple[str, int], ...] = ()
    # a cell of daemons: (input, peer) for each `input X from "peer"`, (input, peer) for each peer
    # whose loss the mission sees (`lost "peer"`), and the internal signals `output … to cell`
    remote_inputs: tuple[tuple[str, str], ...] = ()
    lost_inputs: tuple[tuple[str, str], ...] = ()
    cell_outputs: tuple[str, ...] = ()

    @property
    def fault_mask(self) -> int:
        return sum(bit for _, bit in self.fault_inputs)

    def faults_possible(self, active: Iterable[int]) -> int:
        """The resource faults the environment can raise while tasks `active` run: those of the
        resources none of them runs on."""
        busy = {self.tasks[t].resource for t in active}
        return sum(bit for r, bit in self.fault_inputs if r not in busy)

    def signal(self, name: str) -> str:
        """The full name of a signal as the mission may write it; OrccaddError if unknown or ambiguous."""
        full = self.names.get(name, ())
        if len(full) == 1:
            return full[0]
        what = f"ambiguous ({', '.join(full)})" if full else "unknown"
        raise OrccaddError(
            f"signal {name!r} is {what}; known signals: {', '.join([*self.inputs, *self.internals])}"
        )

    def input_bit(self, name: str) -> int:
        return 1 << self.inputs.index(name)

    def describe_inputs(self, mask: int) -> str:
        names = [n for i, n in enumerate(self.inputs) if mask >> i & 1]
        return "{" + ", ".join(names) + "}"


def sig_names(e: SigExpr) -> list[str]:
    """Every signal name an expression mentions (for messages)."""
    from orccadd.automaton.language import ast as A

    if isinstance(e, A.SigRef):
        return [e.name]
    if isinstance(e, A.Fn):
        return [f"{e.fn}({e.arg})"]
    if isinstance(e, A.Not):
        return sig_names(e.item)
    return [n for i in e.items for n in sig_names(i)]
