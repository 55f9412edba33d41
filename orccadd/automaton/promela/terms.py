"""Kernel terms → Promela processes: the code of the structural spin model (`promela/structure.py`).

One process per branch of every `par` (`proctype b<n>`, created once and reused each time the
`par` starts again); the main and the safe procedure run in process `mission`. A parent drives a
child through two shared bytes: `cmd_b<n>` (1 start, 2 resume, 3 kill; the child puts it back to 0
when its part of the instant is done) and `res_b<n>` (how the child's instant ended: 0 terminated,
1 paused, 2 and up the rank of the trap it exits, in the order of the kernel's completion codes).
Children react one after the other: with every internal signal's status guessed and checked at
the end of the instant, their order does not change the reaction.

A process's code follows the term. `pause`, `halt`, a running task and an `await` are *pause
points*: there the process first lets the enclosing weak aborts (armed ones, innermost first) test
their condition, reports `paused`, and waits for the next instant. Resumed, it obeys a kill from
its parent (stopping what runs at that point), then lets the enclosing strong aborts and `handle`s
test theirs, outermost first, before going on. A `par` whose branches paused is the pause point of
its parent, which kills its paused children when preempted. A trap inside the process is a jump;
an exit of an outer trap is reported to the parent, which kills the branches still paused and
exits in turn (the kernel's max of completion codes).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from orccadd.automaton.language import kernel as K
from orccadd.errors import OrccaddError

START, RESUME, KILL = 1, 2, 3


class Naming(Protocol):
    """How the program's signals and tasks read in the model (`promela_structure.Names`)."""

    def cond(self, c: K.Cond) -> str: ...
    def resolve(self, c: K.Cond) -> list[str]: ...
    def task(self, t: int) -> str: ...
    def task_end(self, t: int) -> str: ...
    def signal(self, bit: int) -> str: ...


@dataclass(frozen=True)
class Frame:
    """An enclosing preemption: a strong or weak abort, or a `handle` with its handlers."""

    kind: str  # "abort", "weak", "handle" or "suspend"
    conds: tuple[K.Cond, ...]
    targets: tuple[str, ...]  # the labels a preemption jumps to
    armed: str = ""  # weak: the process's bit "tested from this instant on"


@dataclass(frozen=True)
class Ctx:
    frames: tuple[Frame, ...]
    traps: Mapping[int, str]  # trap code -> its end label, for the traps inside this process

    def push(self, f: Frame) -> Ctx:
        return Ctx((*self.frames, f), self.traps)


@dataclass(frozen=True)
class WeakReset:
    """At a pause point: every weak-abort bit of the process is 1 when it encloses the point and 0
    otherwise (one state per program point, however it was reached). Rendered once all are known."""

    enclosing: frozenset[str]


@dataclass
class Proc:
    name: str
    child: bool
    lines: list[str | WeakReset] = field(default_factory=list)
    weak: list[str] = field(default_factory=list)
    uses_m: bool = False

    @property
    def cmd(self) -> str:
        return f"cmd_{self.name}"

    @property
    def res(self) -> str:
        return f"res_{self.name}"

    @property
    def fin(self) -> str:
        return f"fin_{self.name}"

    def add(self, *lines: str | WeakReset) -> None:
        self.lines.extend(lines)

    def label(self, name: str) -> None:
        self.lines.append(f"{name}: skip;")

    def render(self) -> list[str]:
        out = [f"active proctype {self.name}() {{"]
        if self.uses_m:
            out.append("  byte m;")
        out += [f"  bit {w};" for w in self.weak]
        # the first statement waits (a `skip` there would be a step spin could take at any time)
        if self.child:
            out += [f"end_idle_{self.name}:", f"  atomic {{ ({self.cmd} == {START});"]
        else:
            out += ["end_boot:", f"  atomic {{ ({self.cmd} != 0);"]
        out += [self._line(x) for x in self.lines]
        if self.child:
            done = f"    {self.resets(frozenset())}{self.cmd} = 0;"
            out += [f"    {self.res} = 0;", f"  {self.fin}:", done, f"    goto end_idle_{self.name}"]
        out += ["  }", "}", ""]
        return out

    def resets(self, enclosing: frozenset[str]) -> str:
        return "".join(f"{w} = {int(w in enclosing)}; " for w in self.weak)

    def _line(self, x: str | WeakReset) -> str:
        if isinstance(x, WeakReset):
            return "    " + (self.resets(x.enclosing).rstrip() or "skip;")
        return ("  " if _LABEL.match(x) else "    ") + x


_LABEL = re.compile(r"\w+: ")


def refuse(what: str) -> OrccaddError:
    return OrccaddError(
        f"the structural Promela model does not cover {what}; export with `--model table` instead"
    )


class Codegen:
    def __init__(self, names: Naming, ranks: Mapping[int, int]) -> None:
        self.names = names
        self.ranks = ranks  # exit code -> res value (2 and up, in the order of the codes)
        self.procs: list[Proc] = []
        self.n = 0
        self.dispatch: dict[type, Callable[[K.Term, Ctx, Proc], None]] = {
            K.Nothing: lambda t, ctx, p: None,
            K.Emit: self._emit,
            K.Seq: self._seq,
            K.Pause: self._pause,
            K.Halt: self._halt,
            K.Await: self._await,
            K.Run: self._run,
            K.Present: self._present,
            K.Loop: self._loop,
            K.Trap: self._trap,
            K.Exit: self._exit,
            K.Abort: self._abort,
            K.Suspend: self._suspend,
            K.Handle: self._handle,
            K.Par: self._par,
        }

    def fresh(self, kind: str) -> str:
        self.n += 1
        return f"{kind}{self.n}"

    def build(self, main: K.Term, safe: K.Term) -> list[Proc]:
        p = Proc("mission", child=False)
        self.procs.append(p)
        self.term(main, Ctx((), {K.SAFE_CODE: "enter_safe"}), p)
        p.add("f_success = 1; goto ended;", "enter_safe: f_safe = 1;")
        self.term(safe, Ctx((), {K.FAILED_CODE: "failed"}), p)
        p.add("f_safe_done = 1; goto ended;", "failed: f_failed = 1;", "ended: skip;", WeakReset(frozenset()))
        p.add("cmd_mission = 0;", "end_ended: (cmd_mission != 0) -> goto ended")
        return self.procs

    def term(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        gen = self.dispatch.get(type(t))
        if gen is None:
            raise refuse(_construct(t))
        gen(t, ctx, p)

    # simple statements ------------------------------------------------------------------------------

    def _emit(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Emit)
        p.add(f"{self.names.signal(t.bit)} = 1;")

    def _seq(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Seq)
        for item in t.parts():
            self.term(item, ctx, p)

    def _pause(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        self.pause(ctx, p, [])

    def _halt(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        p.add(f"goto {self.pause(ctx, p, [])};")

    def _await(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Await)
        c, done = self.names.cond(t.cond), self.fresh("d")
        if t.armed:  # immediate: tested in this instant too
            top = self.fresh("a")
            p.label(top)
            p.add(*self.names.resolve(t.cond), f"if :: {c} -> goto {done} :: else -> skip fi;")
            self.pause(ctx, p, [])
            p.add(f"goto {top};")
        else:
            lab = self.pause(ctx, p, [])
            p.add(*self.names.resolve(t.cond), f"if :: {c} -> skip :: else -> goto {lab} fi;")
        p.label(done)

    def _run(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Run)
        task = self.names.task(t.task)
        p.add(f"start_{task}();  /* line {t.loc.line} */")
        lab = self.pause(ctx, p, [f"kill_{task}()"])
        p.add(f"if :: {self.names.task_end(t.task)} -> stop_{task}() :: else -> goto {lab} fi;")

    def _present(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Present)
        then, after = self.fresh("t"), self.fresh("e")
        p.add(
            *self.names.resolve(t.cond), f"if :: {self.names.cond(t.cond)} -> goto {then} :: else -> skip fi;"
        )
        self.term(t.orelse, ctx, p)
        p.add(f"goto {after};")
        p.label(then)
        self.term(t.then, ctx, p)
        p.label(after)

    def _loop(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Loop)
        top = self.fresh("l")
        p.label(top)
        self.term(t.body, ctx, p)
        p.add(f"goto {top};")

    def _trap(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Trap)
        after = self.fresh("x")
        self.term(t.body, Ctx(ctx.frames, {**ctx.traps, t.code: after}), p)
        p.label(after)

    def _exit(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Exit)
        p.add(self.exit(t.code, ctx, p) + ";")

    def exit(self, code: int, ctx: Ctx, p: Proc) -> str:
        if code in ctx.traps:
            return f"goto {ctx.traps[code]}"
        if p.child:
            return f"{p.res} = {self.ranks[code]}; goto {p.fin}"
        what = (
            "`safe` inside the safe procedure"
            if code == K.SAFE_CODE
            else f"an exit (code {code}) outside its trap"
        )
        raise refuse(what)

    # preemption -------------------------------------------------------------------------------------

    def _abort(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Abort)
        after = self.fresh("u")
        if t.weak:
            bit = self.fresh("wa")
            p.weak.append(bit)
            p.add(f"{bit} = {int(t.armed)};")
            frame = Frame("weak", (t.cond,), (after,), bit)
        else:
            if t.armed:  # tested in the instant it starts (an immediate abort)
                p.add(
                    *self.names.resolve(t.cond),
                    f"if :: {self.names.cond(t.cond)} -> goto {after} :: else -> skip fi;",
                )
            frame = Frame("abort", (t.cond,), (after,))
        self.term(t.body, ctx.push(frame), p)
        p.label(after)

    def _suspend(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        """Every pause point inside tests C when resumed (after the enclosing preemptions outside
        the suspend) and, if it holds, pauses again right there without reacting."""
        assert isinstance(t, K.Suspend)
        if t.armed:  # immediate: while C holds, the body does not start
            top, go = self.fresh("s"), self.fresh("sb")
            p.label(top)
            p.add(
                *self.names.resolve(t.cond),
                f"if :: {self.names.cond(t.cond)} -> skip :: else -> goto {go} fi;",
            )
            self.pause(ctx, p, [])
            p.add(f"goto {top};")
            p.label(go)
        self.term(t.body, ctx.push(Frame("suspend", (t.cond,), ())), p)

    def _handle(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Handle)
        after = self.fresh("h")
        labels = tuple(self.fresh("hd") for _ in t.handlers)
        frame = Frame("handle", t.conds, labels)
        p.add(*self.preempt(frame, []))  # immediate: tested in the instant it starts too
        self.term(t.body, ctx.push(frame), p)
        p.add(f"goto {after};")
        for lab, h in zip(labels, t.handlers, strict=True):
            p.label(lab)
            self.term(h, ctx, p)
            p.add(f"goto {after};")
        p.label(after)

    def preempt(self, f: Frame, cleanup: list[str]) -> list[str]:
        """Lines testing a strong abort's or a handle's conditions (the first that holds wins)."""
        lines: list[str] = []
        for c in f.conds:
            lines += self.names.resolve(c)
        clean = "".join(f"{c}; " for c in cleanup)
        chain = "skip"
        for c, target in reversed(tuple(zip(f.conds, f.targets, strict=True))):
            chain = f"if :: {self.names.cond(c)} -> {clean}goto {target} :: else -> {chain} fi"
        return [*lines, chain + ";"]

    def pause(self, ctx: Ctx, p: Proc, cleanup: list[str]) -> str:
        """A pause point (see the module's docstring); returns its label, to pause there again."""
        lab = self.fresh("p")
        p.label(lab)
        clean = "".join(f"{c}; " for c in cleanup)
        for f in reversed(ctx.frames):
            if f.kind == "weak":
                test = "".join(f"{r} " for r in self.names.resolve(f.conds[0]))
                fire = f"if :: {self.names.cond(f.conds[0])} -> {clean}goto {f.targets[0]} :: else -> skip fi"
                p.add(f"if :: {f.armed} -> {test}{fire} :: else -> skip fi;")
        frozen = self.fresh("z")  # a suspended instant pauses again here, past the weak aborts
        if any(f.kind == "suspend" for f in ctx.frames):
            p.label(frozen)
        p.add(WeakReset(frozenset(f.armed for f in ctx.frames if f.kind == "weak")))
        p.add(f"{p.res} = 1; {p.cmd} = 0;" if p.child else f"{p.cmd} = 0;")
        p.add(f"end_{lab}: ({p.cmd} != 0);")
        if p.child:
            p.add(f"if :: {p.cmd} == {KILL} -> {clean}{p.res} = 0; goto {p.fin} :: else -> skip fi;")
        for f in ctx.frames:
            if f.kind == "suspend":
                c = f.conds[0]
                p.add(
                    *self.names.resolve(c), f"if :: {self.names.cond(c)} -> goto {frozen} :: else -> skip fi;"
                )
            elif f.kind != "weak":
                p.add(*self.preempt(f, cleanup))
        return lab

    # parallel ---------------------------------------------------------------------------------------

    def _par(self, t: K.Term, ctx: Ctx, p: Proc) -> None:
        assert isinstance(t, K.Par)
        if any(b is None for b in t.branches):
            raise refuse("a parallel statement with a terminated branch (a residual term)")
        kids = [self.child(b) for b in t.branches if b is not None]
        p.uses_m = True
        for k in kids:
            p.add(f"cmd_{k} = {START}; (cmd_{k} == 0);")
        join, after = self.fresh("j"), self.fresh("f")
        kill = [f"if :: res_{k} == 1 -> cmd_{k} = {KILL}; (cmd_{k} == 0) :: else -> skip fi" for k in kids]
        p.label(join)
        p.add(
            f"m = res_{kids[0]};",
            *(f"if :: res_{k} > m -> m = res_{k} :: else -> skip fi;" for k in kids[1:]),
        )
        p.add("if", f":: m == 0 -> goto {after}", ":: m == 1 -> m = 0")
        codes: set[int] = set()
        for b in t.branches:
            codes |= escapes(b)
        for code in sorted(codes, reverse=True):
            reset = "".join(f"res_{k} = 0; " for k in kids)
            p.add(f":: m == {self.ranks[code]} -> m = 0; {'; '.join(kill)}; {reset}{self.exit(code, ctx, p)}")
        p.add("fi;")
        self.pause(ctx, p, kill)
        p.add(
            *(f"if :: res_{k} == 1 -> cmd_{k} = {RESUME}; (cmd_{k} == 0) :: else -> skip fi;" for k in kids)
        )
        p.add(f"goto {join};")
        p.label(after)

    def child(self, t: K.Term | None) -> str:
        assert t is not None
        c = Proc(f"b{len(self.procs)}", child=True)
        self.procs.append(c)
        self.term(t, Ctx((), {}), c)
        return c.name


def escapes(t: K.Term | None) -> set[int]:
    """The exit codes a term may end with (its exits to traps outside it, `safe`)."""
    if isinstance(t, K.Exit):
        return {t.code}
    if isinstance(t, K.Trap):
        return escapes(t.body) - {t.code}
    out: set[int] = set()
    for c in K.children(t):
        out |= escapes(c)
    return out


def _construct(t: K.Term) -> str:
    if isinstance(t, K.Running | K.Started):
        return "a task already running (a residual term, not an elaborated program)"
    return f"the construct `{type(t).__name__}`"
