"""Semantic checks and expansion: syntax tree → `Program` (kernel terms, resolved signals).

Checks: one mission name, one main and one safe procedure; no name declared twice or spelt like a
keyword; tasks on declared resources, signatures agreeing with their task files; every signal
known (short names only when unambiguous); only internal signals emitted; procedures not
recursive; `exit` inside its trap; no `safe` inside the safe procedure; no loop body that can end
in the instant it starts; no task in two branches of one `par` (it would be active twice at once).

Besides the program's terms it records the `Site`s the dead-code check follows (task activations,
`emit`s, branches), each with the kernel term that starts it.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterable
from functools import partial
from pathlib import Path

from orccadd.automaton.language import ast as A
from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.program import (
    BUILTIN_T2,
    EVENT_KINDS,
    Program,
    Site,
    TaskInfo,
    event_full_name,
)
from orccadd.errors import MissionError, OrccaddError
from orccadd.types import BUILTIN_T3, TASK_TIMEOUT, TaskFileReader

# Words that would be read as a keyword where a name can stand (statements, signal expressions).
_RESERVED = (
    "run nothing pause halt safe emit await immediate when until do weak loop seq par present then else "
    "trap in exit every handle on end fatal and or not never eventually alternate suspend"
)
KEYWORDS = frozenset(_RESERVED.split())
PROPERTY_FNS = ("active", "start", "stop")
_TRAP_TOP = 500_000
_SAFE_ENDED = _TRAP_TOP + 1  # the trap around the safe procedure: above every trap inside it


def elaborate(m: A.MissionAst, task_files: TaskFileReader | None = None) -> Program:
    """Check a parsed mission and build its program. `task_files` reads the interface of a task
    declared `from "file.toml"` (the task package's `read_task_interface`); without it, such a
    declaration is refused."""
    return _Elaborator(m, task_files).run()


# Procedures are expanded at each call: bound the result's depth and size (each a MissionError).
MAX_EXPANDED_NESTING = 200
MAX_EXPANDED_STATEMENTS = 100_000


class _Elaborator:
    def __init__(self, m: A.MissionAst, task_files: TaskFileReader | None) -> None:
        self.m = m
        self.task_files = task_files
        self.inputs: list[str] = []
        self.input_task: list[int] = []
        self.input_kind: list[str] = []
        self.full: dict[str, tuple[str, int]] = {}  # full name -> ("in"|"int", bit)
        self.short: dict[str, list[str]] = {}  # short name -> full names
        self.internals: list[str] = []
        self.tasks: dict[str, TaskInfo] = {}
        self.procs: dict[str, A.ProcDecl] = {}
        self.declared: dict[str, A.Loc] = {}
        self.nesting = 0  # statements open around the one being elaborated, procedures expanded
        self.expanded = 0  # statements elaborated so far, procedures expanded at each call
        self.runs: list[tuple[int, str]] = []  # every task activation so far: (task, where)
        self.sites: list[Site | None] = []  # None: reserved for a branch being elaborated
        self.open_sites: list[int] = []  # the branches around the statement being elaborated

    def err(self, loc: A.Loc, msg: str) -> MissionError:
        return MissionError(loc.file, loc.line, loc.col, msg, self.m.text)

    # declarations ---------------------------------------------------------------------------------

    def declare(self, name: str, loc: A.Loc, what: str) -> None:
        if name.lower() in KEYWORDS:
            raise self.err(loc, f"`{name}` is a keyword and cannot name a {what}")
        if name in self.declared:
            first = self.declared[name]
            raise self.err(loc, f"`{name}` is already declared at line {first.line}")
        self.declared[name] = loc

    def resource_part(self, name: str, loc: A.Loc, resources: dict[str, A.Loc], what: str) -> None:
        """`R.X`: R must be a declared resource, X not `fault` (the mission's own input)."""
        if "." not in name:
            return
        r, x = name.split(".", 1)
        if r not in resources:
            have = f"declared resources: {', '.join(resources)}" if resources else f"add `resource {r}`"
            raise self.err(loc, f"`{name}` names resource `{r}`'s {what}, but `{r}` is not declared ({have})")
        if x == "fault":
            raise self.err(loc, f"`{name}` is the mission's own input for {r}'s faults: declare nothing")

    def add_input(self, full: str, task: int, kind: str, short: str) -> None:
        self.full[full] = ("in", 1 << len(self.inputs))
        self.inputs.append(full)
        self.input_task.append(task)
        self.input_kind.append(kind)
        self.short.setdefault(short, []).append(full)

    def run(self) -> Program:
        m = self.m
        top = A.Loc(m.file, 1, 1)
        if not m.name:
            raise self.err(top, "the file needs a `mission NAME` line")
        resources = {}
        for r in m.resources:
            self.declare(r.name, r.loc, "resource")
            resources[r.name] = r.loc
        for i in m.inputs:
            self.declare(i.name, i.loc, "signal")
            self.resource_part(i.name, i.loc, resources, "input")
            self.add_input(i.name, -1, "operator", i.name)
        lost = self.lost_inputs()
        for s in m.signals:
            self.declare(s.name, s.loc, "signal")
            self.resource_part(s.name, s.loc, resources, "output")
            self.full[s.name] = ("int", 1 << len(self.internals))
            self.internals.append(s.name)
            self.short.setdefault(s.name, []).append(s.name)
        operator_mask = (1 << len(self.inputs)) - 1
        faults: list[tuple[str, int]] = []
        for name in resources:
            self.add_input(f"{name}.fault", -1, "fault", f"{name}.fault")
            faults.append((name, 1 << (len(self.inputs) - 1)))
        fault_mask = sum(bit for _, bit in faults)
        for t in m.tasks:
            self.declare(t.name, t.loc, "task")
            if t.resource not in resources:
                hint = (
                    f"; declared resources: {', '.join(resources)}"
                    if resources
                    else "; add `resource " + t.resource + "`"
                )
                raise self.err(
                    t.resource_loc,
                    f"task {t.name} runs on `{t.resource}`, which is not a declared resource{hint}",
                )
            self.tasks[t.name] = self.task(t, len(self.tasks))
        for proc in m.procedures:
            self.declare(proc.name, proc.loc, "procedure")
            self.procs[proc.name] = proc
        mains = [p for p in m.procedures if p.role == "main"]
        safes = [p for p in m.procedures if p.role == "safe"]
        if len(mains) != 1:
            where = mains[1].loc if len(mains) > 1 else top
            raise self.err(where, f"a mission needs exactly one `main procedure` (found {len(mains)})")
        if len(safes) != 1:
            where = safes[1].loc if len(safes) > 1 else top
            raise self.err(
                where,
                "a mission needs exactly one `safe procedure`, what runs after a type 3 exception "
                f"(found {len(safes)})",
            )
        tasks = tuple(self.tasks.values())
        main = _guard_main(self.proc_term(mains[0], [], in_safe=False), fault_mask)
        safe_proc = safes[0]
        safe_body = self.branch(
            f"the safe procedure {safe_proc.name}", safe_proc.loc,
            lambda: self.proc_term(safe_proc, [], in_safe=True), kind="safe",
        )  # fmt: skip
        safe = _guard_safe(safe_body, self.t3_of(safe_body) | fault_mask)
        for prop in m.properties:
            self.check_prop(prop)
        return Program(
            name=m.name,
            file=m.file,
            text=m.text,
            inputs=tuple(self.inputs),
            input_task=tuple(self.input_task),
            input_kind=tuple(self.input_kind),
            internals=tuple(self.internals),
            tasks=tasks,
            operator_mask=operator_mask,
            end_masks=tuple(t.mask("post", "T2", "T3") for t in tasks),
            event_masks=tuple(t.mask(*EVENT_KINDS) for t in tasks),
            t3_masks=tuple(t.mask("T3") for t in tasks),
            main=main,
            safe=safe,
            properties=m.properties,
            ast=m,
            names=self.spellings(),
            sites=tuple(site for site in self.sites if site is not None),
            fault_inputs=tuple(faults),
            remote_inputs=tuple((i.name, i.link) for i in m.inputs if i.link),
            lost_inputs=tuple(lost),
            cell_outputs=tuple(sg.name for sg in m.signals if sg.link == A.CELL),
        )

    def lost_inputs(self) -> list[tuple[str, str]]:
        """An input `lost_P` for each peer P the mission takes an input from or tests `lost "P"`
        of: an environment input like an operator's (the cell may lose P in any instant)."""
        m = self.m
        peers: dict[str, A.Loc] = {}
        for d in (*[i for i in m.inputs if i.link], *m.lost):
            peers.setdefault(d.link or d.name, d.loc)
        out: list[tuple[str, str]] = []
        named: dict[str, str] = {}
        for peer, loc in peers.items():
            name = A.lost_input(peer)
            if name in named:
                raise self.err(loc, f'peers "{named[name]}" and "{peer}" cannot both be told apart ({name})')
            named[name] = peer
            self.declare(name, loc, "signal")
            self.add_input(name, -1, "operator", name)
            out.append((name, peer))
        return out

    def task(self, t: A.TaskDecl, index: int) -> TaskInfo:
        declared: list[tuple[str, str, A.Loc]] = [(e.kind, e.name, e.loc) for e in t.events]
        joints = t.joints
        if t.source:
            joints = self.check_against_file(t, declared)
        elif t.params:
            raise self.err(t.params[0].loc, f'task {t.name}: `set` needs a task file (`from "file.toml"`)')
        seen: dict[tuple[str, str], A.Loc] = {}
        for kind, name, loc in declared:
            if (kind, name) in seen:
                raise self.err(loc, f"task {t.name} declares {kind} {name or ''} twice".replace("  ", " "))
            seen[(kind, name)] = loc
        for name in BUILTIN_T3:
            seen.setdefault(("T3", name), t.loc)
        if ("pre", "") in seen:  # a task with preconditions may time out waiting for them
            for name in BUILTIN_T2:
                seen.setdefault(("T2", name), t.loc)
        events: list[tuple[str, str, int]] = []
        for kind in EVENT_KINDS:
            for k, name in seen:
                if k != kind:
                    continue
                full = event_full_name(t.name, kind, name)
                self.add_input(full, index, kind, name or ("done" if kind == "post" else "pre"))
                if kind not in ("post", "pre"):
                    self.short.setdefault(f"{t.name}.{name}", []).append(full)
                events.append((kind, full, self.full[full][1]))
        return TaskInfo(index, t.name, t.resource, joints, t.source, t.loc, tuple(events))

    def check_against_file(self, t: A.TaskDecl, declared: list[tuple[str, str, A.Loc]]) -> tuple[str, ...]:
        """The task file is the truth: the mission's declaration must agree with its signature."""
        path = Path(t.source)
        if not path.is_absolute():
            path = Path(t.loc.file).parent / path
        if self.task_files is None:
            raise self.err(t.loc, f"task {t.name}: no task-file reader was given to read {path}")
        try:
            spec = self.task_files(path)
        except OrccaddError as e:
            raise self.err(t.loc, f"task {t.name}: cannot read its task file: {e}") from None
        has: dict[str, set[str]] = {
            "post": {""} if spec.has_post else set(),
            "pre": {""} if spec.has_pre else set(),
            "T2": set(spec.t2),
            "T3": set(spec.t3) | ({TASK_TIMEOUT} if spec.times_out else set()),
            "sync": set(spec.sync),
        }
        for kind, name, loc in declared:
            if name not in has[kind]:
                what = f"{kind} event {name}" if name else f"{kind}condition"
                offered = ", ".join(f"{k} {n}".strip() for k in EVENT_KINDS for n in sorted(has[k])) or "none"
                msg = f"signature mismatch: {path} declares no {what} for {t.name} (it has: {offered})"
                raise self.err(loc, msg)
        modules = set(spec.modules)
        for ps in t.params:
            if ps.module not in modules:
                known = ", ".join(sorted(modules))
                raise self.err(
                    ps.loc, f"task {t.name}: {path} has no module {ps.module!r} (modules: {known})"
                )
        for kind, names in has.items():
            for n in sorted(names):
                if (kind, n) not in {(k, nm) for k, nm, _ in declared}:
                    declared.append((kind, n, t.loc))
        if t.joints and spec.joints and set(t.joints) != set(spec.joints):
            raise self.err(
                t.loc,
                f"signature mismatch: {path} claims joints {list(spec.joints)}, not {list(t.joints)}",
            )
        return t.joints or spec.joints

    def spellings(self) -> dict[str, tuple[str, ...]]:
        out = {name: tuple(dict.fromkeys(full)) for name, full in self.short.items()}
        out.update({full: (full,) for full in self.full})
        return out

    # signals --------------------------------------------------------------------------------------

    def resolve(self, name: str, loc: A.Loc) -> tuple[str, int]:
        if name in self.full:
            return self.full[name]
        cands = self.short.get(name, [])
        if len(cands) == 1:
            return self.full[cands[0]]
        if len(cands) > 1:
            raise self.err(loc, f"`{name}` is ambiguous: write one of {', '.join(cands)}")
        head = name.split(".")[0]
        if head in self.procs:
            raise self.err(loc, f"`{name}` is a procedure, not a signal")
        if name in self.tasks:
            raise self.err(loc, f"`{name}` is a task, not a signal: did you mean {name}.done?")
        if head in self.tasks:
            own = [f for f in self.inputs if f.startswith(head + ".")]
            raise self.err(
                loc, f"task {head} has no event `{name[len(head) + 1 :]}`; its events: {', '.join(own)}"
            )
        near = difflib.get_close_matches(name, list(dict.fromkeys([*self.full, *self.short])), n=3)
        hint = f"; did you mean {' or '.join(near)}?" if near else ""
        raise self.err(loc, f"unknown signal `{name}`{hint}")

    def cond(self, e: A.SigExpr) -> K.Cond:
        if isinstance(e, A.SigRef):
            where, bit = self.resolve(e.name, e.loc)
            return (K.IN, bit) if where == "in" else (K.INT, bit)
        if isinstance(e, A.Fn):
            if e.fn.lower() == "pre":
                where, bit = self.resolve(e.arg, e.loc)
                return (K.PIN, bit) if where == "in" else (K.PINT, bit)
            raise self.err(
                e.loc, f"`{e.fn}(...)` may only appear in a property; a statement tests signals (or `pre(S)`)"
            )
        if isinstance(e, A.Not):
            return K.NOT, self.cond(e.item)
        op = K.AND if isinstance(e, A.And) else K.OR
        parts = [self.cond(i) for i in e.items]
        if op == K.OR and all(p[0] == K.IN for p in parts):
            mask = 0
            for p in parts:
                mask |= p[1]
            return K.IN, mask
        return _balanced(op, parts)

    def check_prop(self, p: A.PropDecl) -> None:
        for e in (p.a, p.b):
            if e is not None:
                self.check_prop_expr(e)

    def check_prop_expr(self, e: A.SigExpr) -> None:
        if isinstance(e, A.SigRef):
            self.resolve(e.name, e.loc)
        elif isinstance(e, A.Fn) and e.fn == "pre":  # a signal in the previous instant
            self.resolve(e.arg, e.loc)
        elif isinstance(e, A.Fn):
            if e.fn not in PROPERTY_FNS:
                raise self.err(
                    e.loc,
                    f"unknown property atom `{e.fn}(...)`: use {', '.join(PROPERTY_FNS)} or pre(SIGNAL)",
                )
            if e.arg not in self.tasks:
                raise self.err(e.loc, f"`{e.fn}({e.arg})`: {e.arg} is not a declared task")
        elif isinstance(e, A.Not):
            self.check_prop_expr(e.item)
        else:
            for i in e.items:
                self.check_prop_expr(i)

    # statements -----------------------------------------------------------------------------------

    def proc_term(
        self, p: A.ProcDecl, stack: list[str], *, in_safe: bool, via: tuple[tuple[str, A.Loc], ...] = ()
    ) -> K.Term:
        if p.name in stack:
            cycle = " -> ".join([*stack[stack.index(p.name) :], p.name])
            raise self.err(
                p.loc, f"procedure {p.name} calls itself ({cycle}); procedures cannot be recursive"
            )
        scope = _Scope(stack=[*stack, p.name], traps={}, depth=0, in_safe=in_safe, via=via)
        body = self.stmt(p.body, scope)
        if p.handlers:
            body = self.handle(body, p.handlers, scope)
        return body

    def handle(self, body: K.Term, handlers: Iterable[A.Handler], scope: _Scope) -> K.Term:
        conds: list[K.Cond] = []
        terms: list[K.Term] = []
        for h in handlers:
            if h.cond is None:
                mask = self.t3_of(body)
                if not mask:
                    raise self.err(
                        h.loc, "`on fatal` here guards no Robot-Task (nothing can raise a type 3 exception)"
                    )
                conds.append((K.IN, mask))
            else:
                conds.append(self.cond(h.cond))
            what = "the handler `on " + ("fatal" if h.cond is None else A.show(h.cond)) + "`"
            terms.append(self.branch(what, h.loc, partial(self.stmt, h.body, scope)))
        return K.Handle(body, tuple(conds), tuple(terms))

    # what the dead-code check follows -------------------------------------------------------------

    def add_site(self, kind: str, what: str, loc: A.Loc, term: K.Term) -> None:
        parent = self.open_sites[-1] if self.open_sites else -1
        self.sites.append(Site(kind, what, loc, term, parent))

    def branch(self, what: str, loc: A.Loc, build: Callable[[], K.Term], kind: str = "branch") -> K.Term:
        """Elaborate a branch (`build()`) and record it as a site, the parent of the sites inside."""
        index = len(self.sites)
        parent = self.open_sites[-1] if self.open_sites else -1
        self.sites.append(None)
        self.open_sites.append(index)
        try:
            term = build()
        finally:
            self.open_sites.pop()
        self.sites[index] = Site(kind, what, loc, _anchor(term), parent)
        return term

    def place(self, loc: A.Loc, sc: _Scope) -> str:
        """Where a statement is, with the procedure calls that brought it here."""
        chain = "; ".join(f"in {name}, called at {at}" for name, at in reversed(sc.via))
        return f"{loc} ({chain})" if chain else str(loc)

    def par(self, s: A.Par, sc: _Scope) -> K.Term:
        """A parallel statement; a task run in two of its branches is refused (it would be active
        twice at once: one control law cannot run twice on its resource), naming both places."""
        branches: list[K.Term] = []
        earlier: dict[int, str] = {}  # task -> where an earlier branch runs it
        for b in s.branches:
            first_run = len(self.runs)
            branches.append(self.stmt(b, sc))
            mine: dict[int, str] = {}
            for task, where in self.runs[first_run:]:
                mine.setdefault(task, where)
            for task, where in mine.items():
                if task in earlier:
                    name = self.m.tasks[task].name
                    msg = (f"task {name} may be active twice at once: two branches of this `par` run it, "
                           f"at {earlier[task]} and at {where}; a Robot-Task is one control law on its "
                           "resource: run it in one branch only")  # fmt: skip
                    raise self.err(s.loc, msg)
            for task, where in mine.items():
                earlier.setdefault(task, where)
        return K.Par(tuple(branches))

    def t3_of(self, t: K.Term) -> int:
        by_index = {info.index: info for info in self.tasks.values()}
        mask = 0
        for i in _tasks_in(t):
            mask |= by_index[i].mask("T3")
        return mask

    def stmt(self, s: A.Stmt, sc: _Scope) -> K.Term:
        self.nesting += 1
        self.expanded += 1
        try:
            if self.nesting > MAX_EXPANDED_NESTING:
                names = sc.stack if len(sc.stack) <= 8 else [*sc.stack[:3], "…", *sc.stack[-3:]]
                via = " -> ".join(names)
                msg = (f"statements nested more than {MAX_EXPANDED_NESTING} deep once the procedures "
                       f"are expanded (through {via})")  # fmt: skip
                raise self.err(s.loc, msg)
            if self.expanded > MAX_EXPANDED_STATEMENTS:
                msg = (
                    f"the mission expands to more than {MAX_EXPANDED_STATEMENTS} statements (every call "
                    "of a procedure is a copy of its body): call fewer procedures from procedures"
                )
                raise self.err(s.loc, msg)
            return self._stmt(s, sc)
        finally:
            self.nesting -= 1

    def _stmt(self, s: A.Stmt, sc: _Scope) -> K.Term:
        if isinstance(s, A.Seq):
            return K.seq([self.stmt(i, sc) for i in s.items])
        if isinstance(s, A.Call | A.Run):
            if s.name in self.tasks:
                run = K.Run(self.tasks[s.name].index, s.loc)
                self.runs.append((run.task, self.place(s.loc, sc)))
                self.add_site("task", f"task {s.name}", s.loc, run)
                return run
            if isinstance(s, A.Call) and s.name in self.procs:
                p = self.procs[s.name]
                if p.role == "main":
                    raise self.err(s.loc, f"{s.name} is the main procedure; it cannot be called")
                if p.role == "safe":
                    raise self.err(
                        s.loc, f"{s.name} is the safe procedure: enter it with `safe`, not by calling it"
                    )
                return self.proc_term(p, sc.stack, in_safe=sc.in_safe, via=(*sc.via, (p.name, s.loc)))
            if s.name in self.full or s.name in self.short:
                raise self.err(s.loc, f"`{s.name}` is a signal: to wait for it write `await {s.name}`")
            known = [*self.tasks, *self.procs]
            near = difflib.get_close_matches(s.name, known, n=3)
            hint = f"; did you mean {' or '.join(near)}?" if near else ""
            raise self.err(s.loc, f"unknown task or procedure `{s.name}`{hint}")
        if isinstance(s, A.Nothing):
            return K.NOTHING
        if isinstance(s, A.Pause):
            return K.Pause()
        if isinstance(s, A.Halt):
            return K.Halt(s.loc)
        if isinstance(s, A.Safe):
            if sc.in_safe:
                raise self.err(s.loc, "`safe` inside the safe procedure: it is already running")
            return K.Exit(K.SAFE_CODE)
        if isinstance(s, A.Emit):
            where, bit = self.resolve(s.name, s.loc)
            if where != "int":
                msg = (f"cannot emit `{s.name}`: only `signal`s declared in the mission can be emitted "
                       "(operator inputs and task events come from outside)")  # fmt: skip
                raise self.err(s.loc, msg)
            emit = K.Emit(bit)
            self.add_site("emit", f"`emit {s.name}`", s.loc, emit)
            return emit
        if isinstance(s, A.Await):
            return K.Await(self.cond(s.cond), s.immediate, s.loc)
        if isinstance(s, A.When):
            wait = K.Await(self.cond(s.cond), True, s.loc)
            what = f"the body of `when {A.show(s.cond)}`"
            body = self.branch(what, s.body.loc, partial(self.stmt, s.body, sc))
            if s.until is not None:
                body = K.Abort(body, self.cond(s.until), False, False)
            return K.seq((wait, body))
        if isinstance(s, A.DoUntil):
            return K.Abort(self.stmt(s.body, sc), self.cond(s.cond), s.weak, s.immediate)
        if isinstance(s, A.Suspend):
            return K.Suspend(self.stmt(s.body, sc), self.cond(s.cond), s.immediate)
        if isinstance(s, A.Loop):
            body = self.stmt(s.body, sc)
            if K.DONE in first_codes(body):
                msg = ("this loop's body can end in the instant it starts, so the loop would never pause; "
                       "put a task, an `await` or a `pause` on every path through it")  # fmt: skip
                raise self.err(s.loc, msg)
            return K.Loop(body, s.loc)
        if isinstance(s, A.Par):
            return self.par(s, sc)
        if isinstance(s, A.Present):
            return self.present(s, sc)
        if isinstance(s, A.Trap):
            if s.name in sc.traps:
                raise self.err(s.loc, f"trap {s.name} is already open here (line {sc.traps[s.name][1].line})")
            code = _TRAP_TOP - sc.depth
            inner = _Scope(sc.stack, {**sc.traps, s.name: (code, s.loc)}, sc.depth + 1, sc.in_safe, sc.via)
            return K.Trap(code, self.stmt(s.body, inner))
        if isinstance(s, A.Exit):
            if s.name not in sc.traps:
                open_ = ", ".join(sc.traps) or "none"
                raise self.err(
                    s.loc, f"`exit {s.name}` is not inside `trap {s.name}` (open traps here: {open_})"
                )
            return K.Exit(sc.traps[s.name][0])
        if isinstance(s, A.Every):
            c = self.cond(s.cond)
            what = f"the body of `every {A.show(s.cond)}`"
            each = self.branch(what, s.body.loc, partial(self.stmt, s.body, sc))
            body = K.Abort(K.seq((each, K.Halt(s.loc))), c, False, False)
            return K.seq((K.Await(c, False, s.loc), K.Loop(body, s.loc)))
        if isinstance(s, A.Handle):
            return self.handle(self.stmt(s.body, sc), s.handlers, sc)
        raise AssertionError(f"unhandled statement {s!r}")  # pragma: no cover

    def present(self, s: A.Present, sc: _Scope) -> K.Term:
        cond = A.show(s.cond)
        then = self.branch(f"the `then` of `present {cond}`", s.then.loc, partial(self.stmt, s.then, sc))
        orelse: K.Term = K.NOTHING
        if s.orelse is not None:
            what = f"the `else` of `present {cond}`"
            orelse = self.branch(what, s.orelse.loc, partial(self.stmt, s.orelse, sc))
        return K.Present(self.cond(s.cond), then, orelse)


class _Scope:
    __slots__ = ("depth", "in_safe", "stack", "traps", "via")

    def __init__(
        self,
        stack: list[str],
        traps: dict[str, tuple[int, A.Loc]],
        depth: int,
        in_safe: bool,
        via: tuple[tuple[str, A.Loc], ...] = (),
    ) -> None:
        self.stack = stack
        self.traps = traps
        self.depth = depth
        self.in_safe = in_safe
        self.via = via  # the procedure calls that led here: (procedure, where it is called)


def _guard_main(body: K.Term, faults: int) -> K.Term:
    """The main procedure, left for the safe procedure in the instant a resource faults while no
    task of the mission runs on it (`R.fault`): an immediate strong preemption around all of it,
    so a resource's fault enters the safe procedure wherever the main procedure is."""
    if not faults:
        return body
    return K.Handle(body, ((K.IN, faults),), (K.Exit(K.SAFE_CODE),))


def _guard_safe(body: K.Term, t3: int) -> K.Term:
    """The safe procedure, ended as *failed* by a type 3 exception of one of its own tasks or a
    resource's fault: from the instant after it is entered on (a non-immediate strong abort, like
    every other guard), not in that instant, whose type 3 exception or fault caused the entry (the
    safe procedure may run that task again)."""
    ended = K.Exit(_SAFE_ENDED)
    guarded = K.Abort(K.seq((body, ended)), (K.IN, t3), False, False)
    return K.Trap(_SAFE_ENDED, K.seq((guarded, K.Exit(K.FAILED_CODE))))


def _anchor(t: K.Term) -> K.Term:
    """The term whose start is a branch's start: its first statement that is not `nothing` (a
    sequence is spliced into the one around it, its items are kept); `K.NOTHING` if none."""
    if isinstance(t, K.Seq):
        return next((item for item in t.items if item is not K.NOTHING), K.NOTHING)
    return t


def _balanced(op: int, parts: list[K.Cond]) -> K.Cond:
    """`a op b op c …` as a balanced tree: a chain of a thousand operands nests ten deep."""
    while len(parts) > 1:
        pairs = [(op, parts[i], parts[i + 1]) for i in range(0, len(parts) - 1, 2)]
        parts = [*pairs, parts[-1]] if len(parts) % 2 else pairs
    return parts[0]


def _tasks_in(t: K.Term | None) -> set[int]:
    """Every Robot-Task a term may run."""
    if t is None:
        return set()
    if isinstance(t, K.Run | K.Running | K.Started):
        return {t.task}
    out: set[int] = set()
    for child in K.children(t):
        out |= _tasks_in(child)
    return out


def first_codes(t: K.Term) -> set[int]:
    """Completion codes a term may return in the instant it starts (an over-approximation)."""
    if isinstance(t, K.Nothing | K.Emit):
        return {K.DONE}
    if isinstance(t, K.Pause | K.Halt | K.Run | K.Running | K.Started):
        return {K.PAUSED}
    if isinstance(t, K.Await):
        return {K.DONE, K.PAUSED} if t.armed else {K.PAUSED}
    if isinstance(t, K.Exit):
        return {t.code}
    if isinstance(t, K.Present):
        return first_codes(t.then) | first_codes(t.orelse)
    if isinstance(t, K.Seq):
        acc: set[int] = set()
        for item in t.items:
            codes = first_codes(item)
            acc |= codes - {K.DONE}
            if K.DONE not in codes:
                return acc
        return acc | {K.DONE}
    if isinstance(t, K.Par):
        acc = {K.DONE}
        for b in t.branches:
            codes = first_codes(b) if b is not None else {K.DONE}
            acc = {max(x, y) for x in acc for y in codes}
        return acc
    if isinstance(t, K.Loop):
        return first_codes(t.body) - {K.DONE}
    if isinstance(t, K.Abort):
        codes = first_codes(t.body)
        return codes | {K.DONE} if t.armed else codes
    if isinstance(t, K.Suspend):
        codes = first_codes(t.body)
        return codes | {K.PAUSED} if t.armed else codes
    if isinstance(t, K.Trap):
        return {K.DONE if c == t.code else c for c in first_codes(t.body)}
    if isinstance(t, K.Handle):
        acc = first_codes(t.body)
        for h in t.handlers:
            acc |= first_codes(h)
        return acc
    return {K.DONE}
