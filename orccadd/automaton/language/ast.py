"""The mission language's syntax tree: frozen dataclasses, every node carrying where it was written."""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Loc:
    file: str
    line: int
    col: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


# Signal expressions -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SigRef:
    name: str  # as written: `Stabilized`, `KeepStableUS.T2.Stabilized`, `MoveHome.done`
    loc: Loc


@dataclass(frozen=True)
class Fn:
    """A property atom about a task: `active(T)`, `start(T)`, `stop(T)`; in a statement's
    condition, `pre(S)`: S was present in the previous instant."""

    fn: str
    arg: str
    loc: Loc


@dataclass(frozen=True)
class Not:
    item: SigExpr
    loc: Loc


@dataclass(frozen=True)
class And:
    items: tuple[SigExpr, ...]
    loc: Loc


@dataclass(frozen=True)
class Or:
    items: tuple[SigExpr, ...]
    loc: Loc


SigExpr = SigRef | Fn | Not | And | Or


# Statements ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Call:
    """A bare name: run a Robot-Task, or expand a procedure."""

    name: str
    loc: Loc


@dataclass(frozen=True)
class Run:
    name: str
    loc: Loc


@dataclass(frozen=True)
class Nothing:
    loc: Loc


@dataclass(frozen=True)
class Pause:
    loc: Loc


@dataclass(frozen=True)
class Halt:
    loc: Loc


@dataclass(frozen=True)
class Safe:
    loc: Loc


@dataclass(frozen=True)
class Emit:
    name: str
    loc: Loc


@dataclass(frozen=True)
class Await:
    cond: SigExpr
    immediate: bool
    loc: Loc


@dataclass(frozen=True)
class When:
    """`when S do P end` (wait for S, this instant included, then P) or `when S do P until C`."""

    cond: SigExpr
    body: Stmt
    until: SigExpr | None
    loc: Loc


@dataclass(frozen=True)
class DoUntil:
    """`do P until C`: strong preemption; `weak do P until C`: P reacts in the last instant too.
    `immediate`: C is tested in the instant the statement starts too (Esterel's `abort P when
    immediate C`): a strong one then does not start P at all."""

    body: Stmt
    cond: SigExpr
    weak: bool
    loc: Loc
    immediate: bool = False


@dataclass(frozen=True)
class Suspend:
    """`suspend P when C` (Esterel): in an instant where C holds, P does not react at all (its
    state is kept, its tasks' events in that instant are not seen); from the next instant on, or
    in the instant it starts too with `immediate`."""

    body: Stmt
    cond: SigExpr
    loc: Loc
    immediate: bool = False


@dataclass(frozen=True)
class Loop:
    body: Stmt
    loc: Loc


@dataclass(frozen=True)
class Seq:
    items: tuple[Stmt, ...]
    loc: Loc


@dataclass(frozen=True)
class Par:
    branches: tuple[Stmt, ...]
    loc: Loc


@dataclass(frozen=True)
class Present:
    cond: SigExpr
    then: Stmt
    orelse: Stmt | None
    loc: Loc


@dataclass(frozen=True)
class Trap:
    name: str
    body: Stmt
    loc: Loc


@dataclass(frozen=True)
class Exit:
    name: str
    loc: Loc


@dataclass(frozen=True)
class Every:
    cond: SigExpr
    body: Stmt
    loc: Loc


@dataclass(frozen=True)
class Handler:
    """`on C do H`: C is a signal expression, or None for `fatal` (every type 3 exception)."""

    cond: SigExpr | None
    body: Stmt
    loc: Loc


@dataclass(frozen=True)
class Handle:
    body: Stmt
    handlers: tuple[Handler, ...]
    loc: Loc


Stmt = (
    Call
    | Run
    | Nothing
    | Pause
    | Halt
    | Safe
    | Emit
    | Await
    | When
    | DoUntil
    | Suspend
    | Loop
    | Seq
    | Par
    | Present
    | Trap
    | Exit
    | Every
    | Handle
)


# Declarations -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EventDecl:
    kind: str  # post, pre, T2, T3, sync
    name: str  # empty for post/pre
    loc: Loc


@dataclass(frozen=True)
class ParamSet:
    """`set MODULE.PARAM = value` in a task declaration: this instance's parameter value."""

    module: str
    param: str
    value: float | tuple[float, ...]
    loc: Loc


@dataclass(frozen=True)
class TaskDecl:
    name: str
    resource: str
    joints: tuple[str, ...]  # empty: the whole resource
    source: str  # task file the signature is checked against, or ""
    events: tuple[EventDecl, ...]
    loc: Loc
    resource_loc: Loc
    params: tuple[ParamSet, ...] = ()


@dataclass(frozen=True)
class ProcDecl:
    name: str
    role: str  # "main", "safe" or ""
    body: Stmt
    handlers: tuple[Handler, ...]
    loc: Loc


@dataclass(frozen=True)
class PropDecl:
    name: str
    kind: str  # never, eventually, alternate
    a: SigExpr
    b: SigExpr | None
    loc: Loc


@dataclass(frozen=True)
class NameDecl:
    name: str
    loc: Loc
    link: str = ""  # an input `from "peer"`: the peer; a signal `output … to cell`: "cell"


@dataclass(frozen=True)
class MissionAst:
    file: str
    text: str
    name: str
    resources: tuple[NameDecl, ...]
    inputs: tuple[NameDecl, ...]
    signals: tuple[NameDecl, ...]
    tasks: tuple[TaskDecl, ...]
    procedures: tuple[ProcDecl, ...]
    properties: tuple[PropDecl, ...]
    lost: tuple[NameDecl, ...] = ()  # each `lost "peer"` of a condition: the peer, where


CELL = "cell"


def lost_input(peer: str) -> str:
    """The input standing for `lost "peer"` (the cell lost that daemon): `lost_arm_a`."""
    return "lost_" + re.sub(r"[^A-Za-z0-9_]", "_", peer)


def substatements(s: Stmt) -> list[Stmt]:
    """The statements directly inside `s` (handler bodies included)."""
    if isinstance(s, Seq):
        return list(s.items)
    if isinstance(s, Par):
        return list(s.branches)
    if isinstance(s, When | DoUntil | Suspend | Loop | Trap | Every):
        return [s.body]
    if isinstance(s, Present):
        return [s.then] if s.orelse is None else [s.then, s.orelse]
    if isinstance(s, Handle):
        return [s.body, *(h.body for h in s.handlers)]
    return []


def show(e: SigExpr) -> str:
    """A signal expression as it would be written."""
    if isinstance(e, SigRef):
        return e.name
    if isinstance(e, Fn):
        return f"{e.fn}({e.arg})"
    if isinstance(e, Not):
        return f"not {show(e.item)}"
    sep = " and " if isinstance(e, And) else " or "
    return "(" + sep.join(show(i) for i in e.items) + ")"
