"""The kernel of the mission language and its synchronous semantics (one reaction per instant).

A mission is elaborated (`language/elaborate.py`) into a kernel term; a *reaction* rewrites the term given
the input signals present in the instant and returns the residual term (the program's next state),
a completion code and the actions. Esterel's completion codes: 0 terminated, 1 paused (alive),
k ≥ 2 exit of the trap with code k (outer traps have larger codes, so a parallel takes the max).

Signals an instant can hold: inputs (operator inputs and Robot-Task events, bits of `inputs`) and
internal signals the program emits (bits of `emitted`). An internal signal's status in an instant
is resolved by *logical correctness*: the program must have exactly one consistent status
assignment for the signals it both tests and emits (`react` in `reaction.py`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from orccadd.automaton.language.ast import Loc

DONE = 0
PAUSED = 1
SAFE_CODE = 1_000_000  # `safe`: the outermost exit, caught by the mission itself
FAILED_CODE = 999_999  # a type 3 exception inside the safe procedure

# Conditions are small tuples, cheap to hash and to evaluate:
#   (IN, mask): some input bit of mask present       (INT, mask): some internal bit present
#   (AND, a, b) (OR, a, b) (NOT, a)                    (TRUE,)
#   (PIN, mask): `pre(S)` of an input, present in the previous instant   (PINT, mask): of an internal
IN, INT, AND, OR, NOT, TRUE, PIN, PINT = 0, 1, 2, 3, 4, 5, 6, 7
Cond = tuple[Any, ...]


@dataclass(frozen=True, slots=True)
class Nothing:
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Pause:
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Halt:
    loc: Loc
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Emit:
    bit: int
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Present:
    cond: Cond
    then: Term
    orelse: Term
    _h: int = field(default=0, init=False, repr=False, compare=False)


class _Shared:
    """What every residual of one sequence shares: its items' suffix hashes (a residual's hash in
    O(1)) and, per program, what each suffix may test (`mentions` in O(1))."""

    __slots__ = ("hashes", "mentions")

    def __init__(self, items: tuple[Term, ...]) -> None:
        h = [0] * (len(items) + 1)
        for k in range(len(items) - 1, -1, -1):
            h[k] = hash((items[k], h[k + 1]))
        self.hashes = h
        self.mentions: dict[tuple[int, ...], list[tuple[int, int]]] = {}


@dataclass(frozen=True, slots=True, eq=False)
class Seq:
    """`P1; P2; …; Pn` (n ≥ 2), flat: a sequence of hundreds of tasks is one term, not a chain
    hundreds deep (every function over terms recurses on nesting only). Build with `seq`.

    A residual (the sequence under way at its item `start`, that item now `head`) shares `items`
    with the sequence as written: a state of a sequence of n tasks costs O(1), not O(n), and its
    hash and `mentions` come from what the residuals share. Equal and hashed as the sequence it
    stands for, `(first, *rest)`, whatever tuple holds it."""

    items: tuple[Term, ...]
    start: int = 0
    head: Term | None = None  # None: items[start] itself
    _shared: _Shared | None = field(default=None, repr=False)
    _h: int = field(default=0, init=False, repr=False)

    @property
    def first(self) -> Term:
        return self.items[self.start] if self.head is None else self.head

    def rest(self) -> tuple[Term, ...]:
        """The items after the first (a copy: O(n); the step does not need it)."""
        return self.items[self.start + 1 :]

    def parts(self) -> tuple[Term, ...]:
        return (self.first, *self.rest())

    def shared(self) -> _Shared:
        s = self._shared
        if s is None:
            s = _Shared(self.items)
            object.__setattr__(self, "_shared", s)
        return s

    def at(self, i: int, head: Term) -> Term:
        """The residual paused in item i, which became `head`."""
        if i == len(self.items) - 1:
            return head
        if isinstance(head, Seq):  # flat, as `seq` builds it
            return seq((*head.parts(), *self.items[i + 1 :]))
        return Seq(self.items, i, head, self.shared())

    def __hash__(self) -> int:
        h = self._h
        if h == 0:
            h = hash(("Seq", self.first, self.shared().hashes[self.start + 1])) or 1
            object.__setattr__(self, "_h", h)
        return h

    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        if not isinstance(other, Seq):
            return NotImplemented
        if hash(self) != hash(other) or self.first != other.first:
            return False
        if self.items is other.items and self.start == other.start:
            return True
        return self.rest() == other.rest()


@dataclass(frozen=True, slots=True)
class Par:
    branches: tuple[Term | None, ...]  # None: a branch that terminated, waiting for the join
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Loop:
    body: Term
    loc: Loc
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Abort:
    """`do P until C` (strong) or `weak do P until C`. `armed`: C is tested from this instant on."""

    body: Term
    cond: Cond
    weak: bool
    armed: bool
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Suspend:
    """`suspend P when C`: when C holds (from the instant `armed`), P does not react."""

    body: Term
    cond: Cond
    armed: bool
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Await:
    cond: Cond
    armed: bool
    loc: Loc
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Trap:
    code: int
    body: Term
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Exit:
    code: int
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Run:
    """Activate a Robot-Task; it stays active until its postcondition, a type 2 or a type 3 exception."""

    task: int
    loc: Loc
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Running:
    task: int
    loc: Loc
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Started:
    """A task activated in this very instant (settled into `Running` when the instant ends)."""

    task: int
    loc: Loc
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Handle:
    """`handle P on C1 do H1 on C2 do H2 end`: immediate strong preemption of P, the first matching
    handler takes over in the same instant."""

    body: Term
    conds: tuple[Cond, ...]
    handlers: tuple[Term, ...]
    _h: int = field(default=0, init=False, repr=False, compare=False)


@dataclass(frozen=True, slots=True)
class Hole:
    """A `par` compiled apart as a network of branch automata (`compiler/network.py`). Its completion code
    in an instant is given to the context's compilation like an input (`Instant.hole_code`), and
    the instant records whether the context steps it (afresh or not), and whether it kills it
    before or after. `alive`: started in an earlier instant. At most one per mission, stepped at
    most once per instant (`HoleTwiceError` otherwise: a loop ending and restarting it at once)."""

    loc: Loc
    alive: bool
    _h: int = field(default=0, init=False, repr=False, compare=False)


Term = (
    Nothing
    | Pause
    | Halt
    | Emit
    | Present
    | Seq
    | Par
    | Loop
    | Abort
    | Suspend
    | Await
    | Trap
    | Exit
    | Run
    | Running
    | Started
    | Handle
    | Hole
)
NOTHING = Nothing()


def seq(items: tuple[Term, ...] | list[Term]) -> Term:
    """The sequence of `items`, flattened (a `Seq` item's own items are spliced in)."""
    flat: list[Term] = []
    for t in items:
        if isinstance(t, Seq):
            flat.extend(t.parts())
        else:
            flat.append(t)
    return flat[0] if len(flat) == 1 else Seq(tuple(flat))


def _cache_hash(cls: type) -> None:
    """Terms are hashed at every state lookup; each computes its (recursive) hash once."""
    names = tuple(f.name for f in fields(cls) if f.name != "_h")
    tag = cls.__name__

    def cached_hash(self: Any) -> int:
        h: int = self._h
        if h == 0:
            h = hash((tag, *(getattr(self, n) for n in names))) or 1
            object.__setattr__(self, "_h", h)
        return h

    cls.__hash__ = cached_hash  # type: ignore[method-assign,assignment]


for _cls in (
    Nothing,
    Pause,
    Halt,
    Emit,
    Present,
    Par,
    Loop,
    Abort,
    Suspend,
    Await,
    Trap,
    Exit,
    Run,
    Running,
    Started,
    Handle,
    Hole,
):
    _cache_hash(_cls)  # (Seq hashes itself: see the class)


class HoleTwiceError(Exception):
    """A `Hole` stepped twice in one instant (it ended and a loop started it again)."""

    def __init__(self, loc: Loc) -> None:
        super().__init__(loc)
        self.loc = loc


class InstantaneousLoopError(Exception):
    """A loop body terminated in the instant it started: the reaction would never end."""

    def __init__(self, loc: Loc) -> None:
        super().__init__(loc)
        self.loc = loc


class Instant:
    """What one evaluation of one instant reads and does."""

    __slots__ = (
        "assumed",
        "cancelled",
        "emitted",
        "end_masks",
        "hole_code",
        "hole_fresh",
        "hole_killed",
        "hole_killed_first",
        "hole_stepped",
        "inputs",
        "prev_in",
        "prev_int",
        "reads",
        "started",
        "stopped",
    )

    def __init__(self, inputs: int, assumed: int, end_masks: tuple[int, ...]) -> None:
        self.inputs = inputs
        self.assumed = assumed  # guessed statuses of the internal signals (checked afterwards)
        self.end_masks = end_masks  # per task: the input bits that end it (post, T2, T3)
        self.emitted = 0
        self.reads = 0
        self.started: list[int] = []
        self.stopped: list[int] = []
        self.cancelled: list[int] = []
        self.prev_in = 0  # the previous instant's inputs and emitted signals that `pre(S)` tests
        self.prev_int = 0
        self.hole_code = PAUSED  # a `Hole`'s completion code in this instant (compiler/network.py)
        self.hole_stepped = False
        self.hole_fresh = False  # the step started it afresh
        self.hole_killed = False  # killed after the step, or without one
        self.hole_killed_first = False  # killed, then started afresh (a loop around an abort)

    def test(self, c: Cond) -> bool:
        op = c[0]
        if op == IN:
            return (self.inputs & int(c[1])) != 0
        if op == INT:
            self.reads |= int(c[1])
            return (self.assumed & int(c[1])) != 0
        if op == AND:
            return self.test(c[1]) and self.test(c[2])
        if op == OR:
            return self.test(c[1]) or self.test(c[2])
        if op == NOT:
            return not self.test(c[1])
        if op == PIN:
            return (self.prev_in & int(c[1])) != 0
        if op == PINT:
            return (self.prev_int & int(c[1])) != 0
        return True

    def kill(self, t: Term | None) -> None:
        """A paused term is preempted: its running tasks are stopped (or never started)."""
        if t is None:
            return
        if isinstance(t, Running):
            self.stopped.append(t.task)
        elif isinstance(t, Started):
            self.cancelled.append(t.task)
        elif isinstance(t, Seq):
            self.kill(t.first)  # the rest has not started yet
        elif isinstance(t, Par):
            for b in t.branches:
                self.kill(b)
        elif isinstance(t, Abort | Trap | Handle | Suspend):
            self.kill(t.body)
        elif isinstance(t, Hole):
            self.hole_killed = True


def step(t: Term, r: Instant) -> tuple[int, Term]:
    """One instant of `t`: (completion code, residual term; meaningful when the code is PAUSED)."""
    if isinstance(t, Running | Started):
        if r.inputs & r.end_masks[t.task]:
            r.stopped.append(t.task)
            return DONE, NOTHING
        return PAUSED, t
    if isinstance(t, Seq):
        items, i = t.items, t.start
        k, res = step(t.first, r)
        while True:
            if k == PAUSED:
                return PAUSED, t.at(i, res)
            if k != DONE:
                return k, NOTHING
            i += 1
            if i == len(items):
                return DONE, NOTHING
            k, res = step(items[i], r)
    if isinstance(t, Par):
        codes: list[int] = []
        rest: list[Term | None] = []
        for b in t.branches:
            if b is None:
                codes.append(DONE)
                rest.append(None)
                continue
            k, res = step(b, r)
            codes.append(k)
            rest.append(res if k == PAUSED else None)
        top = max(codes)
        if top == PAUSED:
            return PAUSED, Par(tuple(rest))
        if top > PAUSED:
            for paused in rest:
                r.kill(paused)
        return top, NOTHING
    if isinstance(t, Abort):
        if t.armed and not t.weak and r.test(t.cond):
            r.kill(t.body)
            return DONE, NOTHING
        k, body = step(t.body, r)
        if k != PAUSED:
            return k, NOTHING
        if t.armed and t.weak and r.test(t.cond):
            r.kill(body)
            return DONE, NOTHING
        return PAUSED, Abort(body, t.cond, t.weak, True)
    if isinstance(t, Suspend):
        if t.armed and r.test(t.cond):
            return PAUSED, t  # frozen: the body does not react in this instant
        k, body = step(t.body, r)
        return (PAUSED, Suspend(body, t.cond, True)) if k == PAUSED else (k, NOTHING)
    if isinstance(t, Await):
        if t.armed and r.test(t.cond):
            return DONE, NOTHING
        return PAUSED, t if t.armed else Await(t.cond, True, t.loc)
    if isinstance(t, Handle):
        for cond, handler in zip(t.conds, t.handlers, strict=True):
            if r.test(cond):
                r.kill(t.body)
                return step(handler, r)
        k, body = step(t.body, r)
        return (PAUSED, Handle(body, t.conds, t.handlers)) if k == PAUSED else (k, NOTHING)
    if isinstance(t, Loop):
        k, body = step(t.body, r)
        if k == DONE:
            raise InstantaneousLoopError(t.loc)
        return (PAUSED, seq((body, t))) if k == PAUSED else (k, NOTHING)
    if isinstance(t, Trap):
        k, body = step(t.body, r)
        if k == PAUSED:
            return PAUSED, Trap(t.code, body)
        return (DONE if k in (DONE, t.code) else k), NOTHING
    if isinstance(t, Run):
        r.started.append(t.task)
        return PAUSED, Started(t.task, t.loc)
    if isinstance(t, Present):
        return step(t.then if r.test(t.cond) else t.orelse, r)
    if isinstance(t, Hole):
        if r.hole_stepped:
            raise HoleTwiceError(t.loc)
        r.hole_stepped, r.hole_fresh = True, not t.alive
        if r.hole_killed:
            r.hole_killed, r.hole_killed_first = False, True
        k = r.hole_code
        return k, (Hole(t.loc, True) if k == PAUSED else NOTHING)
    if isinstance(t, Emit):
        r.emitted |= t.bit
        return DONE, NOTHING
    if isinstance(t, Exit):
        return t.code, NOTHING
    if isinstance(t, Pause):
        return PAUSED, NOTHING
    if isinstance(t, Halt):
        return PAUSED, t
    return DONE, NOTHING  # Nothing


def settle(t: Term) -> Term:
    """End of the instant: tasks started in it become plain `Running` (one state, however reached)."""
    if isinstance(t, Started):
        return Running(t.task, t.loc)
    if isinstance(t, Seq):
        first = settle(t.first)
        return t if first is t.first else t.at(t.start, first)
    if isinstance(t, Par):
        return Par(tuple(None if b is None else settle(b) for b in t.branches))
    if isinstance(t, Abort):
        return Abort(settle(t.body), t.cond, t.weak, t.armed)
    if isinstance(t, Suspend):
        return Suspend(settle(t.body), t.cond, t.armed)
    if isinstance(t, Trap):
        return Trap(t.code, settle(t.body))
    if isinstance(t, Handle):
        return Handle(settle(t.body), t.conds, t.handlers)
    return t


def children(t: Term | None) -> list[Term | None]:
    """The sub-terms of a statement (a terminated `par` branch is None)."""
    if isinstance(t, Seq):
        return list(t.parts())
    if isinstance(t, Par):
        return list(t.branches)
    if isinstance(t, Abort | Loop | Trap | Suspend):
        return [t.body]
    if isinstance(t, Present):
        return [t.then, t.orelse]
    if isinstance(t, Handle):
        return [t.body, *t.handlers]
    return []


def conds(t: Term | None) -> tuple[Cond, ...]:
    """The conditions a statement itself tests (not its sub-terms')."""
    if isinstance(t, Await | Abort | Present | Suspend):
        return (t.cond,)
    if isinstance(t, Handle):
        return t.conds
    return ()


def active_tasks(t: Term | None, out: list[int]) -> list[int]:
    """The Robot-Tasks a paused term keeps active."""
    if isinstance(t, Running | Started):
        out.append(t.task)
    elif isinstance(t, Seq):
        active_tasks(t.first, out)
    elif isinstance(t, Par):
        for b in t.branches:
            active_tasks(b, out)
    elif isinstance(t, Abort | Trap | Handle | Suspend):
        active_tasks(t.body, out)
    return out


def cond_masks(c: Cond) -> tuple[int, int]:
    """(input bits, internal bits) a condition mentions."""
    if c[0] == IN:
        return int(c[1]), 0
    if c[0] == INT:
        return 0, int(c[1])
    if c[0] == PIN:  # this instant's input decides the next instant's pre(S): relevant now
        return int(c[1]), 0
    if c[0] in (TRUE, PINT):  # pre of an internal signal: last instant's, not guessed now
        return 0, 0
    ins, ints = 0, 0
    for sub in c[1:]:
        a, b = cond_masks(sub)
        ins |= a
        ints |= b
    return ins, ints


def mentions(t: Term | None, end_masks: tuple[int, ...]) -> tuple[int, int]:
    """(input bits, internal bits) the term may test from now on (an over-approximation)."""
    if t is None:
        return 0, 0
    if isinstance(t, Running | Started | Run):
        return end_masks[t.task], 0
    if isinstance(t, Await):
        return cond_masks(t.cond)
    if isinstance(t, Seq):
        return _union(mentions(t.first, end_masks), _suffix_mentions(t, end_masks)[t.start + 1])
    if isinstance(t, Par):
        acc = (0, 0)
        for b in t.branches:
            acc = _union(acc, mentions(b, end_masks))
        return acc
    if isinstance(t, Abort | Suspend):
        return _union(cond_masks(t.cond), mentions(t.body, end_masks))
    if isinstance(t, Loop | Trap):
        return mentions(t.body, end_masks)
    if isinstance(t, Present):
        return _union(cond_masks(t.cond), _union(mentions(t.then, end_masks), mentions(t.orelse, end_masks)))
    if isinstance(t, Handle):
        acc = mentions(t.body, end_masks)
        for c, h in zip(t.conds, t.handlers, strict=True):
            acc = _union(acc, _union(cond_masks(c), mentions(h, end_masks)))
        return acc
    return 0, 0


def pre_masks(*terms: Term | None) -> tuple[int, int]:
    """(input bits, internal bits) some `pre(S)` of the terms tests: what a state must remember of
    the instant before."""
    pin = pint = 0
    stack: list[Any] = [t for t in terms if t is not None]
    while stack:
        x = stack.pop()
        if isinstance(x, tuple):  # a condition
            if x and x[0] == PIN:
                pin |= int(x[1])
            elif x and x[0] == PINT:
                pint |= int(x[1])
            elif x and x[0] in (AND, OR, NOT):
                stack.extend(x[1:])
            continue
        stack.extend(conds(x))
        stack.extend(c for c in children(x) if c is not None)
    return pin, pint


def _suffix_mentions(t: Seq, end_masks: tuple[int, ...]) -> list[tuple[int, int]]:
    """What each suffix of `t.items` may test (index k: items[k:]), computed once per sequence."""
    shared = t.shared()
    out = shared.mentions.get(end_masks)
    if out is None:
        items = t.items
        out = [(0, 0)] * (len(items) + 1)
        for k in range(len(items) - 1, -1, -1):
            out[k] = _union(mentions(items[k], end_masks), out[k + 1])
        shared.mentions[end_masks] = out
    return out


def _union(a: tuple[int, int], b: tuple[int, int]) -> tuple[int, int]:
    return a[0] | b[0], a[1] | b[1]
