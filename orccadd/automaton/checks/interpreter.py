"""A direct interpreter of the mission language, written independently of the compiler.

It walks the *syntax tree* with one mutable object per statement (start / resume / kill), where
the compiler rewrites kernel terms; the two must agree instant by instant (a property test feeds
both random programs and random inputs). It is the reference for the semantics, not for speed.
Internal signals are resolved the same way (exactly one consistent status per instant), by
re-running the instant on a copy of the program for every guess; and that status must be the one
constructive semantics establishes (Esterel's rule): each node's `potential` is its instant in
three-valued logic (what it must emit, what it can, its completion codes), signals present when
they must be emitted, absent when they cannot be, iterated; computed on the syntax tree's nodes,
apart from the compiler's (`compiler/constructive.py`, on kernel terms).
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Callable

from orccadd.automaton.compiler.explicit import ActionLayout
from orccadd.automaton.language import ast as A
from orccadd.automaton.language.program import Program
from orccadd.errors import OrccaddError

DONE, PAUSED = 0, 1
SAFE_CODE, FAILED_CODE = 1_000_000, 999_999


class InterpreterError(OrccaddError):
    """The program has no single reaction (non-causal) or loops within an instant."""


class Ctx:
    def __init__(self, p: Program, inputs: int, assumed: int, instant: int) -> None:
        self.p = p
        self.inputs = inputs
        self.assumed = assumed
        self.instant = instant
        self.emitted = 0
        self.reads = 0
        self.starts: list[int] = []
        self.stops: list[int] = []
        self.prev_inputs = 0  # the previous instant's inputs and emitted signals (`pre(S)`)
        self.prev_emitted = 0
        self.ternary = False  # a `potential`: internal signals `present`, `absent` or not known
        self.present = 0
        self.absent = 0


Pot = tuple[int, int, "int | None", frozenset[int]]  # must emit, can emit, must code, can codes
_NO: frozenset[int] = frozenset()


def _pot(code: int) -> Pot:
    return 0, 0, code, frozenset((code,))


def _either(*pots: Pot, codes: frozenset[int] = _NO) -> Pot:
    """Any of these can happen, none must (a test not decided yet)."""
    can, out = 0, set(codes)
    for _, c, _, k in pots:
        can |= c
        out |= k
    return 0, can, None, frozenset(out)


def _then(first: Pot, rest: Callable[[], Pot]) -> Pot:
    """`first`, then `rest` if `first` can end (DONE) in this instant."""
    must, can, code, codes = first
    if DONE not in codes:
        return first
    m2, c2, k2, ks2 = rest()
    return (
        (must | m2 if code == DONE else must),
        can | c2,
        (k2 if code == DONE else None),
        (codes - {DONE}) | ks2,
    )


def _map(pot: Pot, old: int, new: int) -> Pot:
    must, can, code, codes = pot
    return must, can, (new if code == old else code), frozenset(new if k == old else k for k in codes)


class Node:
    def start(self, c: Ctx) -> int:
        raise NotImplementedError

    def resume(self, c: Ctx) -> int:
        raise NotImplementedError

    def kill(self, c: Ctx) -> None:
        """Preempted while paused."""

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        """This instant of the node (`fresh`: started in it, else resumed) in three-valued logic,
        without changing it."""
        raise NotImplementedError


class Leaf(Node):
    def __init__(self, first: int, then: int) -> None:
        self.first, self.then = first, then

    def start(self, c: Ctx) -> int:
        return self.first

    def resume(self, c: Ctx) -> int:
        return self.then

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        return _pot(self.first if fresh else self.then)


class EmitN(Node):
    def __init__(self, bit: int) -> None:
        self.bit = bit

    def start(self, c: Ctx) -> int:
        c.emitted |= self.bit
        return DONE

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        return self.bit, self.bit, DONE, frozenset((DONE,))


class AwaitN(Node):
    def __init__(self, test: Callable[[Ctx], bool], immediate: bool) -> None:
        self.test, self.immediate = test, immediate

    def start(self, c: Ctx) -> int:
        return DONE if self.immediate and self.test(c) else PAUSED

    def resume(self, c: Ctx) -> int:
        return DONE if self.test(c) else PAUSED

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        if fresh and not self.immediate:
            return _pot(PAUSED)
        v = self.test(c)
        return (0, 0, None, frozenset((DONE, PAUSED))) if v is None else _pot(DONE if v else PAUSED)


class RunN(Node):
    def __init__(self, task: int) -> None:
        self.task = task
        self.since = -1

    def start(self, c: Ctx) -> int:
        c.starts.append(self.task)
        self.since = c.instant
        return PAUSED

    def resume(self, c: Ctx) -> int:
        if c.inputs & c.p.end_masks[self.task]:
            c.stops.append(self.task)
            return DONE
        return PAUSED

    def kill(self, c: Ctx) -> None:
        if self.since == c.instant:
            c.starts.remove(self.task)  # started and preempted in one instant: it never ran
        else:
            c.stops.append(self.task)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        return _pot(PAUSED if fresh or not c.inputs & c.p.end_masks[self.task] else DONE)


class SeqN(Node):
    def __init__(self, items: list[Node]) -> None:
        self.items = items
        self.at = 0

    def _go(self, c: Ctx, code: int) -> int:
        while code == DONE and self.at + 1 < len(self.items):
            self.at += 1
            code = self.items[self.at].start(c)
        return code

    def start(self, c: Ctx) -> int:
        self.at = 0
        return self._go(c, self.items[0].start(c))

    def resume(self, c: Ctx) -> int:
        return self._go(c, self.items[self.at].resume(c))

    def kill(self, c: Ctx) -> None:
        self.items[self.at].kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        at = 0 if fresh else self.at

        def from_(i: int, first: bool) -> Pot:
            pot = self.items[i].potential(c, first)
            return pot if i + 1 == len(self.items) else _then(pot, lambda: from_(i + 1, True))

        return from_(at, fresh)


class ParN(Node):
    def __init__(self, branches: list[Node]) -> None:
        self.branches = branches
        self.alive = [False] * len(branches)

    def _join(self, c: Ctx, codes: list[int]) -> int:
        self.alive = [k == PAUSED for k in codes]
        top = max(codes)
        if top > PAUSED:
            for b, alive in zip(self.branches, self.alive, strict=True):
                if alive:
                    b.kill(c)
        return top

    def start(self, c: Ctx) -> int:
        return self._join(c, [b.start(c) for b in self.branches])

    def resume(self, c: Ctx) -> int:
        return self._join(
            c, [b.resume(c) if alive else DONE for b, alive in zip(self.branches, self.alive, strict=True)]
        )

    def kill(self, c: Ctx) -> None:
        for b, alive in zip(self.branches, self.alive, strict=True):
            if alive:
                b.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        must = can = 0
        code: int | None = DONE
        codes = {DONE}
        for b, alive in zip(self.branches, self.alive, strict=True):
            m, cn, k, ks = b.potential(c, True) if fresh else (b.potential(c, False) if alive else _pot(DONE))
            must, can = must | m, can | cn
            code = None if code is None or k is None else max(code, k)
            codes = {max(x, y) for x in codes for y in ks}
        return must, can, code, frozenset(codes)


class LoopN(Node):
    def __init__(self, body: Node) -> None:
        self.body = body

    def start(self, c: Ctx) -> int:
        code = self.body.start(c)
        if code == DONE:
            raise InterpreterError("instantaneous loop")
        return code

    def resume(self, c: Ctx) -> int:
        code = self.body.resume(c)
        return self.start(c) if code == DONE else code

    def kill(self, c: Ctx) -> None:
        self.body.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        def again() -> Pot:  # a body that ends at once is refused by `start` itself
            must, can, code, codes = self.body.potential(c, True)
            return must, can, (None if code == DONE else code), codes - {DONE}

        return again() if fresh else _then(self.body.potential(c, False), again)


class AbortN(Node):
    def __init__(self, body: Node, test: Callable[[Ctx], bool], weak: bool, immediate: bool = False) -> None:
        self.body, self.test, self.weak, self.immediate = body, test, weak, immediate

    def start(self, c: Ctx) -> int:
        if not self.immediate:
            return self.body.start(c)
        if not self.weak and self.test(c):  # preempted before it starts
            return DONE
        code = self.body.start(c)
        if code == PAUSED and self.weak and self.test(c):
            self.body.kill(c)
            return DONE
        return code

    def resume(self, c: Ctx) -> int:
        if not self.weak and self.test(c):
            self.body.kill(c)
            return DONE
        code = self.body.resume(c)
        if code == PAUSED and self.weak and self.test(c):
            self.body.kill(c)
            return DONE
        return code

    def kill(self, c: Ctx) -> None:
        self.body.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        if fresh and not self.immediate:
            return self.body.potential(c, True)
        if not self.weak:
            v = self.test(c)
            if v:
                return _pot(DONE)
            body = self.body.potential(c, fresh)
            return body if v is False else _either(body, codes=frozenset((DONE,)))
        body = self.body.potential(c, fresh)
        if PAUSED not in body[3]:
            return body
        v = self.test(c)
        if v is False:
            return body
        if v:
            return _map(body, PAUSED, DONE)
        return body[0], body[1], (None if body[2] == PAUSED else body[2]), body[3] | {DONE}


class SuspendN(Node):
    """`suspend P when C`: in an instant where C holds (from the next instant, or this one too if
    immediate), P does not react; an immediate one that holds at once starts P later."""

    def __init__(self, body: Node, test: Callable[[Ctx], bool], immediate: bool) -> None:
        self.body, self.test, self.immediate = body, test, immediate
        self.started = False

    def start(self, c: Ctx) -> int:
        self.started = not (self.immediate and self.test(c))
        return self.body.start(c) if self.started else PAUSED

    def resume(self, c: Ctx) -> int:
        if self.test(c):
            return PAUSED
        if not self.started:
            self.started = True
            return self.body.start(c)
        return self.body.resume(c)

    def kill(self, c: Ctx) -> None:
        if self.started:
            self.body.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        if fresh and not self.immediate:
            return self.body.potential(c, True)
        v = self.test(c)
        if v:
            return _pot(PAUSED)
        body = self.body.potential(c, fresh or not self.started)
        return body if v is False else _either(body, codes=frozenset((PAUSED,)))


class PresentN(Node):
    def __init__(self, test: Callable[[Ctx], bool], then: Node, orelse: Node) -> None:
        self.test, self.then, self.orelse = test, then, orelse
        self.chosen: Node = then

    def start(self, c: Ctx) -> int:
        self.chosen = self.then if self.test(c) else self.orelse
        return self.chosen.start(c)

    def resume(self, c: Ctx) -> int:
        return self.chosen.resume(c)

    def kill(self, c: Ctx) -> None:
        self.chosen.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        if not fresh:
            return self.chosen.potential(c, False)
        v = self.test(c)
        if v is None:
            return _either(self.then.potential(c, True), self.orelse.potential(c, True))
        return (self.then if v else self.orelse).potential(c, True)


class TrapN(Node):
    def __init__(self, code: int, body: Node) -> None:
        self.code, self.body = code, body

    def _catch(self, k: int) -> int:
        return DONE if k == self.code else k

    def start(self, c: Ctx) -> int:
        return self._catch(self.body.start(c))

    def resume(self, c: Ctx) -> int:
        return self._catch(self.body.resume(c))

    def kill(self, c: Ctx) -> None:
        self.body.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        return _map(self.body.potential(c, fresh), self.code, DONE)


class HandleN(Node):
    """Strong preemption by the first handler whose condition holds: immediate (tested in the
    instant the body starts too), or not (the safe procedure's guard: from the next instant on)."""

    def __init__(
        self, body: Node, handlers: list[tuple[Callable[[Ctx], bool], Node]], immediate: bool = True
    ) -> None:
        self.body, self.handlers, self.immediate = body, handlers, immediate
        self.current: Node = body

    def _check(self, c: Ctx, running_body: bool) -> int | None:
        for test, h in self.handlers:
            if test(c):
                if running_body:
                    self.body.kill(c)
                self.current = h
                return h.start(c)
        return None

    def start(self, c: Ctx) -> int:
        self.current = self.body
        code = self._check(c, running_body=False) if self.immediate else None
        return self.body.start(c) if code is None else code

    def resume(self, c: Ctx) -> int:
        if self.current is self.body:
            code = self._check(c, running_body=True)
            if code is not None:
                return code
        return self.current.resume(c)

    def kill(self, c: Ctx) -> None:
        self.current.kill(c)

    def potential(self, c: Ctx, fresh: bool) -> Pot:
        if not fresh and self.current is not self.body:
            return self.current.potential(c, False)
        seen: list[Pot] = []  # handlers that can start while an earlier condition is not known
        if self.immediate or not fresh:
            for test, h in self.handlers:
                v = test(c)
                if v is False:
                    continue
                if v and not seen:
                    return h.potential(c, True)
                seen.append(h.potential(c, True))
                if v:
                    return _either(*seen)
        body = self.body.potential(c, fresh)
        return _either(*seen, body) if seen else body


class Interpreter:
    """Runs a checked `Program` straight from its syntax tree, one `react` per instant."""

    def __init__(self, p: Program) -> None:
        self.p = p
        self.layout = ActionLayout(p)
        self.procs = {d.name: d for d in p.ast.procedures}
        self.task_index = {t.name: t.index for t in p.tasks}
        main = next(d for d in p.ast.procedures if d.role == "main")
        safe = next(d for d in p.ast.procedures if d.role == "safe")
        # a resource's fault (no task on it) enters the safe procedure from anywhere in the main one
        faults = p.fault_mask
        self.main = self.proc(main, 0)
        if faults:
            self.main = HandleN(self.main, [(lambda c: bool(c.inputs & faults), Leaf(SAFE_CODE, SAFE_CODE))])
        safe_body = self.proc(safe, 0)
        t3 = self.t3_mask(self.tasks_of_proc(safe)) | faults
        failed: list[tuple[Callable[[Ctx], bool], Node]] = [
            (lambda c: bool(c.inputs & t3), Leaf(FAILED_CODE, FAILED_CODE))
        ]
        self.safe = HandleN(safe_body, failed, immediate=False)  # the entry's type 3 is the main's
        self.phase = "start"
        self.instant = 0
        self.prev = (0, 0)  # (inputs, emitted) of the previous instant
        self.active: list[int] = []

    # building -------------------------------------------------------------------------------------

    def signal(self, name: str) -> tuple[str, int]:
        p = self.p
        if name in p.inputs:
            return "in", 1 << p.inputs.index(name)
        if name in p.internals:
            return "int", 1 << p.internals.index(name)
        hits = [f for f in p.inputs if f.split(".")[-1] == name and name not in ("done", "pre")]
        if "." in name:  # Task.Event, the kind left out
            head, tail = name.split(".")[0], name.split(".")[-1]
            hits = [f for f in p.inputs if f.split(".")[0] == head and f.split(".")[-1] == tail]
        if len(hits) != 1:
            raise InterpreterError(f"cannot resolve {name}")
        return "in", 1 << p.inputs.index(hits[0])

    def test(self, e: A.SigExpr) -> Callable[[Ctx], bool]:
        if isinstance(e, A.Fn):  # `pre(S)`, the only function a statement's condition may use
            where, bit = self.signal(e.arg)
            if where == "in":
                return lambda c: bool(c.prev_inputs & bit)
            return lambda c: bool(c.prev_emitted & bit)
        if isinstance(e, A.SigRef):
            where, bit = self.signal(e.name)
            if where == "in":
                return lambda c: bool(c.inputs & bit)

            def internal(c: Ctx) -> bool:
                if c.ternary:  # known present, known absent, or not yet (None)
                    return True if c.present & bit else (False if c.absent & bit else None)  # type: ignore[return-value]
                c.reads |= bit
                return bool(c.assumed & bit)

            return internal
        if isinstance(e, A.Not):
            inner = self.test(e.item)
            return lambda c: (lambda v: None if v is None else not v)(inner(c))  # type: ignore[return-value]
        parts = [self.test(x) for x in e.items]  # type: ignore[union-attr]
        conj = isinstance(e, A.And)

        def combined(c: Ctx) -> bool:
            if not c.ternary:
                return all(f(c) for f in parts) if conj else any(f(c) for f in parts)
            values = [f(c) for f in parts]  # one side can decide it: false for `and`, true for `or`
            if (not conj) in values:
                return not conj
            return conj if all(v is conj for v in values) else None  # type: ignore[return-value]

        return combined

    def tasks_of(self, s: A.Stmt) -> set[int]:
        if isinstance(s, A.Call | A.Run):
            if s.name in self.task_index:
                return {self.task_index[s.name]}
            return self.tasks_of_proc(self.procs[s.name])
        out: set[int] = set()
        for sub in A.substatements(s):
            out |= self.tasks_of(sub)
        return out

    def tasks_of_proc(self, d: A.ProcDecl) -> set[int]:
        out = self.tasks_of(d.body)
        for h in d.handlers:
            out |= self.tasks_of(h.body)
        return out

    def t3_mask(self, tasks: set[int]) -> int:
        m = 0
        for t in tasks:
            m |= self.p.t3_masks[t]
        return m

    def proc(self, d: A.ProcDecl, depth: int) -> Node:
        body = self.node(d.body, depth, {})
        if d.handlers:
            body = self.handlers(body, self.tasks_of(d.body), d.handlers, depth, {})
        return body

    def handlers(
        self, body: Node, tasks: set[int], hs: tuple[A.Handler, ...], depth: int, traps: dict[str, int]
    ) -> Node:
        out: list[tuple[Callable[[Ctx], bool], Node]] = []
        for h in hs:
            if h.cond is None:
                m = self.t3_mask(tasks)
                out.append(((lambda c, m=m: bool(c.inputs & m)), self.node(h.body, depth, traps)))  # type: ignore[misc]
            else:
                out.append((self.test(h.cond), self.node(h.body, depth, traps)))
        return HandleN(body, out)

    def node(self, s: A.Stmt, depth: int, traps: dict[str, int]) -> Node:
        if isinstance(s, A.Seq):
            return SeqN([self.node(x, depth, traps) for x in s.items])
        if isinstance(s, A.Call | A.Run):
            if s.name in self.task_index:
                return RunN(self.task_index[s.name])
            return self.proc(self.procs[s.name], depth)
        if isinstance(s, A.Nothing):
            return Leaf(DONE, DONE)
        if isinstance(s, A.Pause):
            return Leaf(PAUSED, DONE)
        if isinstance(s, A.Halt):
            return Leaf(PAUSED, PAUSED)
        if isinstance(s, A.Safe):
            return Leaf(SAFE_CODE, SAFE_CODE)
        if isinstance(s, A.Emit):
            return EmitN(self.signal(s.name)[1])
        if isinstance(s, A.Await):
            return AwaitN(self.test(s.cond), s.immediate)
        if isinstance(s, A.When):
            body = self.node(s.body, depth, traps)
            if s.until is not None:
                body = AbortN(body, self.test(s.until), weak=False)
            return SeqN([AwaitN(self.test(s.cond), immediate=True), body])
        if isinstance(s, A.DoUntil):
            return AbortN(self.node(s.body, depth, traps), self.test(s.cond), s.weak, s.immediate)
        if isinstance(s, A.Suspend):
            return SuspendN(self.node(s.body, depth, traps), self.test(s.cond), s.immediate)
        if isinstance(s, A.Loop):
            return LoopN(self.node(s.body, depth, traps))
        if isinstance(s, A.Par):
            return ParN([self.node(b, depth, traps) for b in s.branches])
        if isinstance(s, A.Present):
            orelse = self.node(s.orelse, depth, traps) if s.orelse is not None else Leaf(DONE, DONE)
            return PresentN(self.test(s.cond), self.node(s.then, depth, traps), orelse)
        if isinstance(s, A.Trap):
            code = 500_000 - depth
            return TrapN(code, self.node(s.body, depth + 1, {**traps, s.name: code}))
        if isinstance(s, A.Exit):
            return Leaf(traps[s.name], traps[s.name])
        if isinstance(s, A.Every):
            test = self.test(s.cond)
            body = SeqN([self.node(s.body, depth, traps), Leaf(PAUSED, PAUSED)])
            return SeqN([AwaitN(test, immediate=False), LoopN(AbortN(body, test, weak=False))])
        if isinstance(s, A.Handle):
            return self.handlers(
                self.node(s.body, depth, traps), self.tasks_of(s.body), s.handlers, depth, traps
            )
        raise InterpreterError(f"unknown statement {s!r}")

    # running --------------------------------------------------------------------------------------

    def react(self, inputs: int) -> int:
        """Inputs present in this instant → the same action bits as the compiled automaton."""
        n_int = len(self.p.internals)
        results: dict[tuple[int, int], tuple[Interpreter, int]] = {}
        reads: dict[tuple[int, int], int] = {}
        for bits in itertools.product((0, 1), repeat=n_int):
            assumed = sum(b << i for i, b in enumerate(bits))
            trial = copy.deepcopy(self)
            c = Ctx(self.p, inputs, assumed, self.instant)
            c.prev_inputs, c.prev_emitted = self.prev
            actions = trial._instant(c)
            if (c.emitted & c.reads) == (assumed & c.reads):
                results[(assumed & c.reads, c.emitted)] = (trial, actions)
                reads[(assumed & c.reads, c.emitted)] = c.reads
        if len(results) != 1:
            raise InterpreterError(f"{len(results)} consistent reactions")
        ((assumed, emitted), (trial, actions)), *_ = results.items()
        if reads[(assumed, emitted)]:  # it tested internal signals
            self._establish(inputs, reads[(assumed, emitted)], assumed)
        self.__dict__.update(trial.__dict__)
        self.instant += 1
        self.prev = (inputs, emitted)
        return actions

    def _establish(self, inputs: int, reads: int, assumed: int) -> None:
        """The statuses constructive semantics gives the signals this instant reads, iterated from
        none known; `InterpreterError` unless every one is established, as the guess found it."""
        present = absent = 0
        every = (1 << len(self.p.internals)) - 1
        while True:
            c = Ctx(self.p, inputs, 0, self.instant)
            c.prev_inputs, c.prev_emitted = self.prev
            c.ternary, c.present, c.absent = True, present, absent
            must, can = self._potential(c)
            more_present = must & ~present
            more_absent = every & ~can & ~absent & ~present
            if not (more_present or more_absent):
                break
            present |= more_present
            absent |= more_absent
        if reads & ~(present | absent) or present & reads != assumed:
            names = [
                n
                for i, n in enumerate(self.p.internals)
                if reads >> i & 1 and not (present | absent) >> i & 1
            ]
            raise InterpreterError(
                f"not constructive: the status of {', '.join(names)} cannot be established"
            )

    def _potential(self, c: Ctx) -> tuple[int, int]:
        """(must emit, can emit) of this instant, main then the safe procedure it may enter."""
        if self.phase == "end":
            return 0, 0
        if self.phase == "safe":
            pot = self.safe.potential(c, False)
            return pot[0], pot[1]
        must, can, code, codes = self.main.potential(c, self.phase == "start")
        if SAFE_CODE in codes:
            smust, scan, _, _ = self.safe.potential(c, True)
            can |= scan
            must |= smust if code == SAFE_CODE else 0
        return must, can

    def _instant(self, c: Ctx) -> int:
        lay = self.layout
        flags = 0
        if self.phase in ("start", "main"):
            code = self.main.start(c) if self.phase == "start" else self.main.resume(c)
            self.phase = "main"
            if code == DONE:
                self.phase, flags = "end", lay.success_bit
            elif code == SAFE_CODE:
                flags = lay.safe_bit | self._safe(c, first=True)
        elif self.phase == "safe":
            flags = self._safe(c, first=False)
        actions = flags | (c.emitted << lay.emit_base)
        for t in c.starts:
            actions |= 1 << (lay.start_base + t)
            self.active.append(t)
        for t in c.stops:
            actions |= 1 << (lay.stop_base + t)
            if t in self.active:
                self.active.remove(t)
        if self.phase == "end":
            self.active = []
        return actions

    def _safe(self, c: Ctx, first: bool) -> int:
        self.phase = "safe"
        code = self.safe.start(c) if first else self.safe.resume(c)
        if code == PAUSED:
            return 0
        self.phase = "end"
        return self.layout.failed_bit if code == FAILED_CODE else self.layout.safe_done_bit
