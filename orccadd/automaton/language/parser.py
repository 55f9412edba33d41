"""Mission text → syntax tree (`language/ast.py`). Every error is a `MissionError` citing file:line:col."""

from __future__ import annotations

import re
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import Any

import lark

from orccadd.automaton.language import ast as A
from orccadd.errors import MissionError

GRAMMAR = Path(__file__).with_name("mission.lark")

# What a user should read instead of lark's terminal names.
_WORDS = {
    "NAME": "a name",
    "STRING": 'a "quoted path"',
    "SEMICOLON": "`;`",
    "LPAR": "`(`",
    "RPAR": "`)`",
    "COMMA": "`,`",
    "COLON": "`:`",
    "DOT": "`.`",
    "__ANON_0": "`||`",
    "__ANON_1": "`->`",
    "EVKIND": "an event kind (post, pre, T2, T3, sync)",
    "PROC_ROLE": "`main` or `safe`",
    "NUMBER": "a number",
    "EQUAL": "`=`",
    "LSQB": "`[`",
    "RSQB": "`]`",
}
# Limits on what a mission may be (each refused with a MissionError that says which): the checks
# run before any recursive pass, so no mission can exhaust the interpreter's stack.
MAX_MISSION_CHARS = 1_000_000
MAX_NESTING = 64  # statements and signal expressions nested inside one another
PEER = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]{0,62}$")  # a daemon's name in a cell (`[cell] robot`)
MAX_COUNT = 1000  # `repeat N times`, `await N C`: N copies in sequence (each counts against the limits)

_NESTING_NODES = frozenset(
    "call run nothing pause halt safe emit await_ when_until when_do do_until weak_do_until loop seq par "
    "present trap exit every handle handler not_ and_expr or_expr".split()
)

_DECL_TOKENS = (
    "MISSION",
    "RESOURCE",
    "INPUT",
    "SIGNAL",
    "OUTPUT",
    "TASK",
    "PROCEDURE",
    "PROC_ROLE",
    "PROPERTY",
)


@cache
def _parser() -> lark.Lark:
    return lark.Lark(GRAMMAR.read_text(), parser="lalr", propagate_positions=True, maybe_placeholders=True)


def _word(terminal: str) -> str:
    if terminal in _WORDS:
        return _WORDS[terminal]
    if terminal.isupper() and terminal.isalpha():
        return f"`{terminal.lower()}`"
    return terminal


def _expected(names: set[str]) -> str:
    words = sorted({_word(n) for n in names if not n.startswith("$")})
    if not words:
        return "the end of the file"
    if len(words) > 8:
        words = [*words[:8], "…"]
    return ", ".join(words)


def parse_mission(text: str, file: str = "<mission>") -> A.MissionAst:
    """Parse a mission; raise `MissionError` (never anything else) on a syntax error."""
    if len(text) > MAX_MISSION_CHARS:
        raise MissionError(
            file, 1, 1, f"the mission is {len(text)} characters long; the limit is {MAX_MISSION_CHARS}"
        )
    try:
        tree = _parser().parse(text)
    except lark.exceptions.UnexpectedToken as e:
        tok = e.token
        missing = _missing_name(text, len(text) if tok.type == "$END" else (tok.start_pos or 0))
        if missing is not None:
            line, col, msg = missing
            raise MissionError(file, line, col, msg, text) from None
        if tok.type == "$END":
            line, col = _end_of(text)
            raise MissionError(
                file, line, col, f"the file ends too early: expected {_expected(e.expected)}", text
            ) from None
        found = f"`{tok}`"
        if "NAME" in e.expected and tok.type != "NAME" and str(tok).isidentifier():
            msg = f"`{tok}` is a keyword and cannot be used as a name here"
        elif tok.type in _DECL_TOKENS and tok.type not in e.expected:
            msg = f"unexpected {found}: the previous declaration is not finished (missing `end`?)"
        else:
            msg = f"unexpected {found}: expected {_expected(e.expected)}"
        raise MissionError(file, tok.line or e.line, tok.column or e.column, msg, text) from None
    except lark.exceptions.UnexpectedCharacters as e:
        pos = e.pos_in_stream or 0
        ch = text[pos] if 0 <= pos < len(text) else "?"
        msg = f"unexpected character {ch!r}: expected {_expected(set(e.allowed))}"
        raise MissionError(file, e.line, e.column, msg, text) from None
    except lark.exceptions.UnexpectedEOF as e:
        line, col = _end_of(text)
        raise MissionError(
            file, line, col, f"the file ends too early: expected {_expected(set(e.expected))}", text
        ) from None
    _check_nesting(tree, file, text)
    return _Builder(file, text).mission(tree)


def _check_nesting(tree: lark.Tree[Any], file: str, text: str) -> None:
    """Refuse nesting deeper than `MAX_NESTING` (iteratively: the tree may be thousands deep)."""
    stack: list[tuple[lark.Tree[Any], int]] = [(tree, 0)]
    while stack:
        node, depth = stack.pop()
        if node.data in _NESTING_NODES:
            depth += 1
            if depth > MAX_NESTING:
                meta = node.meta
                line, col = getattr(meta, "line", 0), getattr(meta, "column", 0)
                msg = f"statements or conditions nested more than {MAX_NESTING} deep here"
                raise MissionError(file, line, col, msg, text)
        stack.extend((c, depth) for c in node.children if isinstance(c, lark.Tree))


# After these words a name must follow; a keyword there was read as that name.
_NAME_FOLLOWS = frozenset("until await emit when every present exit trap immediate not and or".split(" "))
_KEYWORDS_READ_AS_NAMES = (
    "end do then else loop on until when par seq safe pause halt nothing emit await every trap exit handle"
)
_KEYWORD_WORDS = frozenset(_KEYWORDS_READ_AS_NAMES.split())


def _missing_name(text: str, pos: int) -> tuple[int, int, str] | None:
    """`do A until` followed by `end`: the keyword was taken for a signal; say that a name is missing."""
    words = list(re.finditer(r"[A-Za-z_][A-Za-z0-9_]*", _strip_comments(text[:pos])))
    if len(words) < 2:
        return None
    before, last = words[-2], words[-1]
    if before.group().lower() in _NAME_FOLLOWS and last.group().lower() in _KEYWORD_WORDS:
        line = text.count("\n", 0, last.start()) + 1
        col = last.start() - (text.rfind("\n", 0, last.start()) + 1) + 1
        return line, col, f"a name is missing after `{before.group()}` (`{last.group()}` is a keyword)"
    return None


def _strip_comments(text: str) -> str:
    """Comments blanked out, positions kept."""
    return re.sub(r"(--|#)[^\n]*", lambda m: " " * len(m.group()), text)


def _end_of(text: str) -> tuple[int, int]:
    """Line and column just after the last non-blank character (where an EOF error points)."""
    lines = text.rstrip().splitlines() or [""]
    return len(lines), len(lines[-1]) + 1


def load_mission_file(path: str | Path) -> A.MissionAst:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise MissionError(str(path), 0, 0, f"cannot read the mission file: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise MissionError(str(path), 1, 1, f"the mission file is not UTF-8 text ({e.reason})") from None
    return parse_mission(text, str(path))


class _Builder:
    """lark parse tree → frozen syntax tree."""

    def __init__(self, file: str, text: str) -> None:
        self.file = file
        self.text = text
        self.lost: list[A.NameDecl] = []  # `lost "peer"` atoms, in order

    def loc(self, node: Any) -> A.Loc:
        if isinstance(node, lark.Token):
            return A.Loc(self.file, node.line or 0, node.column or 0)
        meta = node.meta
        return A.Loc(self.file, getattr(meta, "line", 0), getattr(meta, "column", 0))

    def err(self, node: Any, msg: str) -> MissionError:
        loc = self.loc(node)
        return MissionError(self.file, loc.line, loc.col, msg, self.text)

    def mission(self, tree: lark.Tree[Any]) -> A.MissionAst:
        name = ""
        resources: list[A.NameDecl] = []
        inputs: list[A.NameDecl] = []
        signals: list[A.NameDecl] = []
        tasks: list[A.TaskDecl] = []
        procs: list[A.ProcDecl] = []
        props: list[A.PropDecl] = []
        for d in tree.children:
            kind = d.data
            if kind == "mission_decl":
                if name:
                    raise self.err(d, "a file holds one mission: a second `mission` line")
                name = str(d.children[1])
            elif kind == "resource_decl":
                resources.extend(self.names(d.children[1]))
            elif kind == "input_decl":
                peer = self.peer(d.children[3]) if d.children[3] is not None else ""
                if peer and any("." in n.name for n in self.signal_names(d.children[1])):
                    raise self.err(d.children[3], "an input from a peer is a plain name (not R.X)")
                inputs.extend(replace(n, link=peer) for n in self.signal_names(d.children[1]))
            elif kind == "signal_decl":
                signals.extend(self.signal_names(d.children[1]))
            elif kind == "output_decl":
                where = d.children[3]
                if str(where) != A.CELL:
                    raise self.err(where, f"`output … to {where}`: an output goes `to cell`")
                named = self.signal_names(d.children[1])
                if any("." in n.name for n in named):
                    raise self.err(d, "an output to the cell is a plain name (not R.Y)")
                signals.extend(replace(n, link=A.CELL) for n in named)
            elif kind == "task_decl":
                tasks.append(self.task(d))
            elif kind == "proc_decl":
                procs.append(self.procedure(d))
            elif kind == "prop_decl":
                props.append(self.prop(d))
        return A.MissionAst(
            self.file, self.text, name, tuple(resources), tuple(inputs), tuple(signals), tuple(tasks),
            tuple(procs), tuple(props), tuple(self.lost),
        )  # fmt: skip

    def peer(self, tok: Any) -> str:
        """A peer's name in the cell, from its string: letters, digits, _ and -."""
        name = str(tok)[1:-1]
        if not PEER.match(name):
            raise self.err(tok, f"peer {tok} must be a daemon's name in the cell (letters, digits, _ or -)")
        return name

    def names(self, node: lark.Tree[Any]) -> list[A.NameDecl]:
        return [A.NameDecl(str(t), self.loc(t)) for t in node.children if isinstance(t, lark.Token)]

    def signal_names(self, node: lark.Tree[Any]) -> list[A.NameDecl]:
        """`S` or `R.X` (a resource's input or output action) for each name of the list."""
        out = []
        for sig in node.children:
            parts = [t for t in sig.children if isinstance(t, lark.Token)]
            out.append(A.NameDecl(".".join(str(t) for t in parts), self.loc(parts[0])))
        return out

    def task(self, d: lark.Tree[Any]) -> A.TaskDecl:
        _, name, _, resource, _, joints, _, source, *items, _ = d.children
        evs: list[A.EventDecl] = []
        params: list[A.ParamSet] = []
        for e in items:
            if e.data == "task_set":
                params.append(self.param_set(e))
                continue
            kind_tok, lst = e.children
            kind = str(kind_tok)
            kind = kind.upper() if kind.lower() in ("t2", "t3") else kind.lower()
            if kind in ("post", "pre"):
                if lst is not None:
                    raise self.err(
                        lst,
                        f"`{kind}` takes no name: the event is called "
                        f"{name}.{'done' if kind == 'post' else 'pre'}",
                    )
                evs.append(A.EventDecl(kind, "", self.loc(kind_tok)))
                continue
            if lst is None:
                raise self.err(kind_tok, f"`{kind}` needs at least one event name")
            evs.extend(A.EventDecl(kind, n.name, n.loc) for n in self.names(lst))
        return A.TaskDecl(
            str(name), str(resource), tuple(n.name for n in self.names(joints)) if joints is not None else (),
            str(source)[1:-1] if source is not None else "", tuple(evs), self.loc(name), self.loc(resource),
            tuple(params),
        )  # fmt: skip

    def param_set(self, e: lark.Tree[Any]) -> A.ParamSet:
        _, module, param, value = e.children
        numbers = [float(t) for t in value.children if isinstance(t, lark.Token)]
        v: float | tuple[float, ...] = numbers[0] if value.data == "number" else tuple(numbers)
        return A.ParamSet(str(module), str(param), v, self.loc(module))

    def procedure(self, d: lark.Tree[Any]) -> A.ProcDecl:
        role, _, name, body, *rest = d.children
        handlers = tuple(self.handler(h) for h in rest[:-1])
        return A.ProcDecl(
            str(name),
            str(role).lower() if role is not None else "",
            self.block(body),
            handlers,
            self.loc(name),
        )

    def handler(self, h: lark.Tree[Any]) -> A.Handler:
        _, cond, _, body = h.children
        c = None if cond.data == "fatal_cond" else self.sexpr(cond.children[0])
        return A.Handler(c, self.block(body), self.loc(h))

    def prop(self, d: lark.Tree[Any]) -> A.PropDecl:
        _, name, p = d.children
        loc = self.loc(name)
        if p.data == "never":
            return A.PropDecl(str(name), "never", self.sexpr(p.children[1]), None, loc)
        if p.data == "eventually":
            return A.PropDecl(
                str(name), "eventually", self.sexpr(p.children[0]), self.sexpr(p.children[2]), loc
            )
        both = self.sexpr(p.children[0])
        if not isinstance(both, A.And) or len(both.items) != 2:
            raise self.err(p, "`alternate` needs exactly two operands: `A and B alternate`")
        return A.PropDecl(str(name), "alternate", both.items[0], both.items[1], loc)

    # statements

    def block(self, b: lark.Tree[Any]) -> A.Stmt:
        items = [self.stmt(s) for s in b.children if isinstance(s, lark.Tree)]
        return items[0] if len(items) == 1 else A.Seq(tuple(items), self.loc(b))

    def await_(self, c: list[Any], loc: A.Loc) -> A.Stmt:
        """`await C`, `await immediate C`, or `await N C` (the N-th C from the next instant on:
        N awaits in sequence, as Esterel defines it)."""
        immediate, count, cond = c[1] is not None, c[2], self.sexpr(c[3])
        if count is None:
            return A.Await(cond, immediate, loc)
        if immediate:
            raise self.err(count, "`await immediate` takes no count: `await N C` waits from the next instant")
        n = self.count(count, "await", f"await {count}")
        return A.Await(cond, False, loc) if n == 1 else A.Seq((A.Await(cond, False, loc),) * n, loc)

    def count(self, token: Any, what: str, shown: str) -> int:
        """A count in the text: a whole number from 1 to `MAX_COUNT`."""
        text = str(token)
        if not text.isdigit() or not 1 <= int(text) <= MAX_COUNT:
            raise self.err(token, f"`{shown}`: the count must be a whole number from 1 to {MAX_COUNT}")
        return int(text)

    def stmt(self, s: lark.Tree[Any]) -> A.Stmt:
        k = s.data
        c = s.children
        loc = self.loc(s)
        if k == "call":
            return A.Call(self.qname(c[0]), loc)
        if k == "run":
            return A.Run(self.qname(c[1]), loc)
        if k in ("nothing", "pause", "halt", "safe"):
            simple: dict[str, type[A.Nothing | A.Pause | A.Halt | A.Safe]] = {
                "nothing": A.Nothing, "pause": A.Pause, "halt": A.Halt, "safe": A.Safe,
            }  # fmt: skip
            return simple[k](loc)
        if k == "emit":
            return A.Emit(self.qname(c[1]), loc)
        if k == "await_":
            return self.await_(c, loc)
        if k == "when_until":
            return A.When(self.sexpr(c[1]), self.block(c[3]), self.sexpr(c[5]), loc)
        if k == "when_do":
            return A.When(self.sexpr(c[1]), self.block(c[3]), None, loc)
        if k == "do_until":
            return A.DoUntil(self.block(c[1]), self.sexpr(c[4]), False, loc, c[3] is not None)
        if k == "weak_do_until":
            return A.DoUntil(self.block(c[2]), self.sexpr(c[5]), True, loc, c[4] is not None)
        if k == "suspend":
            return A.Suspend(self.block(c[1]), self.sexpr(c[4]), loc, c[3] is not None)
        if k == "loop":
            return A.Loop(self.block(c[1]), loc)
        if k == "loop_each":  # Esterel: loop (do P; halt until S) — P restarts at each S
            then_halt = A.Seq((self.block(c[1]), A.Halt(loc)), loc)
            return A.Loop(A.DoUntil(then_halt, self.sexpr(c[3]), False, loc), loc)
        if k == "repeat":  # P, N times in sequence
            n = self.count(c[1], "repeat", f"repeat {c[1]} times")
            once = self.block(c[3])
            return once if n == 1 else A.Seq((once,) * n, loc)
        if k == "seq":
            return self.block(c[1])
        if k == "par":
            return A.Par(tuple(self.block(x) for x in c[1:]), loc)
        if k == "present":
            then = self.block(c[3]) if c[3] is not None else A.Nothing(loc)
            orelse = self.block(c[5]) if c[5] is not None else None
            return A.Present(self.sexpr(c[1]), then, orelse, loc)
        if k == "trap":
            return A.Trap(str(c[1]), self.block(c[3]), loc)
        if k == "exit":
            return A.Exit(str(c[1]), loc)
        if k == "every":
            return A.Every(self.sexpr(c[1]), self.block(c[3]), loc)
        if k == "handle":
            return A.Handle(self.block(c[1]), tuple(self.handler(h) for h in c[2:-1]), loc)
        raise AssertionError(f"unhandled statement {k}")  # pragma: no cover - grammar and builder agree

    def qname(self, q: lark.Tree[Any]) -> str:
        return ".".join(str(t) for t in q.children)

    def sexpr(self, e: Any) -> A.SigExpr:
        k = e.data
        loc = self.loc(e)
        if k == "sig":
            return A.SigRef(self.qname(e.children[0]), loc)
        if k == "lost":
            peer = self.peer(e.children[1])
            self.lost.append(A.NameDecl(peer, loc))
            return A.SigRef(A.lost_input(peer), loc)
        if k == "fn":
            arg = e.children[1]
            return A.Fn(str(e.children[0]), self.qname(arg) if isinstance(arg, lark.Tree) else str(arg), loc)
        if k == "not_":
            return A.Not(self.sexpr(e.children[1]), loc)
        items = tuple(self.sexpr(x) for x in e.children if isinstance(x, lark.Tree))
        return A.And(items, loc) if k == "and_expr" else A.Or(items, loc)
