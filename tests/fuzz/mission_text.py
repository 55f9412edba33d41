"""Grammar-aware mutations of mission texts.

The shipped missions are parsed with the language's own grammar (orccadd/automaton/language/mission.lark)
into lark trees; a mutation edits a tree (statements deleted, duplicated, swapped, moved, nested
hundreds deep; expressions turned into `not not …` or long `or` chains; names, numbers and paths
replaced), then `unparse` prints it back, and a last text-level step may cut it or insert a
random token. Deep or long constructions are inserted as text (`raw` nodes), so no tree gets deep.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from functools import cache
from pathlib import Path

import lark
from hypothesis import strategies as st
from lark import Token, Tree

from orccadd.automaton.language.parser import GRAMMAR

ROOT = Path(__file__).resolve().parents[2]
SEEDS = sorted(
    [*ROOT.glob("configs/missions/*.mission"), *ROOT.glob("tests/**/missions/*.mission")],
    key=str,
)
KEYWORDS = (
    "mission resource input signal task on joints from set end post pre T2 T3 sync main safe procedure "
    "fatal do property never eventually alternate run nothing pause halt emit await immediate when "
    "until weak loop seq par present then else trap in exit every handle or and not"
).split()
PUNCT = ["(", ")", "||", ";", ":", ",", ".", "->", "=", "[", "]", '"', "--", "#", "\n", "\t"]
UNICODE = ["é", "ℌ", "ǅ", "\u200b", "\u202e", "\ufeff", "😀", "\x00", "\x7f", "\ud800", "Ⅻ", "ß"]
STMT_KINDS = (
    "call run nothing pause halt safe emit await_ when_until when_do do_until weak_do_until loop seq par "
    "present trap exit every handle"
).split()
EXPR_PARENTS = {"await_": 1, "when_until": 1, "when_do": 1, "do_until": 3, "weak_do_until": 4, "every": 1}
EXPR_PARENTS |= {"present": 1}


@cache
def _parser() -> lark.Lark:
    return lark.Lark(GRAMMAR.read_text(), parser="lalr", maybe_placeholders=True)


@cache
def seed_tree(path: Path) -> Tree[Token]:
    return _parser().parse(path.read_text())


def raw(text: str) -> Tree[Token]:
    """Text printed as it is (a deep or long construction)."""
    return Tree("raw", [Token("RAW", text)])


# ---- printing --------------------------------------------------------------------------------


def _t(x: object) -> str:
    return "" if x is None else unparse(x) if isinstance(x, Tree) else str(x)


def _expr(x: object) -> str:
    """A sub-expression, in parentheses unless it is a name or a call."""
    s = _t(x)
    return s if isinstance(x, Token) or (isinstance(x, Tree) and x.data in ("sig", "fn", "raw")) else f"({s})"


def _join(xs: Sequence[object], sep: str = " ") -> str:
    return sep.join(s for s in (_t(x) for x in xs) if s)


def unparse(t: Tree[Token]) -> str:
    """Mission text of a (possibly mutated) tree."""
    k, c = str(t.data), t.children
    rules: dict[str, Callable[[], str]] = {
        "start": lambda: "\n\n".join(_t(x) for x in c) + "\n",
        "raw": lambda: str(c[0]),
        "name_list": lambda: ", ".join(_t(x) for x in c),
        "qname": lambda: ".".join(_t(x) for x in c),
        "block": lambda: ";\n".join(_t(x) for x in c),
        "task_set": lambda: f"  set {_t(c[1])}.{_t(c[2])} = {_t(c[3])}",
        "number": lambda: _t(c[0]),
        "vector": lambda: "[" + ", ".join(_t(x) for x in c) + "]",
        "task_decl": lambda: _join(c[:8]) + "\n" + "".join(_t(x) + "\n" for x in c[8:-1]) + _t(c[-1]),
        "task_event": lambda: "  " + _join(c),
        "proc_decl": lambda: _join(c[:3]) + "\n" + _t(c[3]) + "\n" + "".join(_t(x) + "\n" for x in c[4:]),
        "handler": lambda: f"{_t(c[0])} {_t(c[1])} {_t(c[2])}\n{_t(c[3])}",
        "fatal_cond": lambda: _t(c[0]),
        "prop_decl": lambda: f"{_t(c[0])} {_t(c[1])}: {_t(c[2])}",
        "never": lambda: f"{_t(c[0])} {_expr(c[1])}",
        "eventually": lambda: f"{_expr(c[0])} -> {_t(c[1])} {_expr(c[2])}",
        "alternate": lambda: f"{_expr(c[0])} {_t(c[1])}",
        "or_expr": lambda: " ".join(_expr(x) if isinstance(x, Tree) else _t(x) for x in c),
        "and_expr": lambda: " ".join(_expr(x) if isinstance(x, Tree) else _t(x) for x in c),
        "not_": lambda: f"{_t(c[0])} {_expr(c[1])}",
        "sig": lambda: _t(c[0]),
        "fn": lambda: f"{_t(c[0])}({_t(c[1])})",
        "seq": lambda: f"{_t(c[0])}(\n{_t(c[1])}\n)",
        "par": lambda: f"{_t(c[0])}(\n" + "\n||\n".join(_t(x) for x in c[1:]) + "\n)",
        "when_until": lambda: f"{_t(c[0])} {_expr(c[1])} {_t(c[2])}\n{_t(c[3])}\n{_t(c[4])} {_expr(c[5])}",
        "when_do": lambda: f"{_t(c[0])} {_expr(c[1])} {_t(c[2])}\n{_t(c[3])}\n{_t(c[4])}",
        "do_until": lambda: f"{_t(c[0])}\n{_t(c[1])}\n{_t(c[2])} {_expr(c[3])}",
        "weak_do_until": lambda: f"{_t(c[0])} {_t(c[1])}\n{_t(c[2])}\n{_t(c[3])} {_expr(c[4])}",
        "loop": lambda: f"{_t(c[0])}\n{_t(c[1])}\n{_join(c[2:])}",
        "present": lambda: (
            f"{_t(c[0])} {_expr(c[1])}"
            + "".join(f" {_t(c[i])}\n{_t(c[i + 1])}\n" for i in (2, 4) if c[i] is not None)
            + _t(c[6])
        ),
        "trap": lambda: f"{_t(c[0])} {_t(c[1])} {_t(c[2])}\n{_t(c[3])}\n{_t(c[4])}",
        "every": lambda: f"{_t(c[0])} {_expr(c[1])} {_t(c[2])}\n{_t(c[3])}\n{_t(c[4])}",
        "handle": lambda: f"{_t(c[0])}\n{_t(c[1])}\n" + "".join(_t(x) + "\n" for x in c[2:-1]) + _t(c[-1]),
        "await_": lambda: _join(c[:2]) + " " + _expr(c[2]),
    }
    return rules[k]() if k in rules else _join(c)


# ---- mutations -------------------------------------------------------------------------------


def _names(t: Tree[Token], rule: str, index: int) -> list[str]:
    return [str(n.children[index]) for n in t.find_data(rule) if isinstance(n.children[index], Token)]


def _blocks(t: Tree[Token]) -> list[Tree[Token]]:
    return [b for b in t.iter_subtrees() if b.data == "block" and b.children]


NESTS: dict[str, tuple[str, str]] = {
    "seq": ("SEQ(", ")"),
    "do": ("do ", " until {s}"),
    "weak": ("weak do ", " until {s}"),
    "loop": ("loop ", " end loop"),
    "trap": ("trap T in ", " end"),
    "par": ("PAR(", " || nothing)"),
    "present": ("present {s} then ", " end"),
    "handle": ("handle ", " on {s} do nothing end"),
    "every": ("every {s} do ", " end"),
    "when": ("when {s} do ", " end"),
}


@st.composite
def mutated_tree(draw: st.DrawFn, t: Tree[Token]) -> Tree[Token]:
    """`t` with one grammar-level edit."""
    t = copy.deepcopy(t)
    tasks = _names(t, "task_decl", 1) or ["T"]
    sigs = [*tasks, *_names(t, "input_decl", 1), "Stop", *(f"{x}.done" for x in tasks)]
    blocks = _blocks(t)
    op = draw(st.integers(0, 11))
    if op <= 5 and blocks:
        b = draw(st.sampled_from(blocks))
        i = draw(st.integers(0, len(b.children) - 1))
        if op == 0:
            del b.children[i]
        elif op == 1:
            b.children.insert(i, copy.deepcopy(b.children[i]))
        elif op == 2:
            j = draw(st.integers(0, len(b.children) - 1))
            b.children[i], b.children[j] = b.children[j], b.children[i]
        elif op == 3:  # move a statement into another block (not one inside itself)
            other = draw(st.sampled_from(blocks))
            moved = b.children.pop(i)
            if isinstance(moved, Tree) and any(x is other for x in moved.iter_subtrees()):
                other = b
            other.children.insert(draw(st.integers(0, len(other.children))), moved)
        elif op == 4:  # nest a statement deeply
            kinds = draw(st.lists(st.sampled_from(sorted(NESTS)), min_size=1, max_size=3))
            depth = draw(st.integers(1, 20) | st.integers(50, 300))
            s = draw(st.sampled_from(sigs))
            pre = "".join(NESTS[kinds[d % len(kinds)]][0].format(s=s) for d in range(depth))
            post = "".join(NESTS[kinds[d % len(kinds)]][1].format(s=s) for d in reversed(range(depth)))
            b.children[i] = raw(pre + unparse_or_raw(b.children[i]) + post)
        else:  # a long sequence of task calls
            n = draw(st.integers(2, 20) | st.integers(100, 600))
            names = draw(st.lists(st.sampled_from(tasks), min_size=1, max_size=3))
            b.children[i] = raw(";\n".join(names[k % len(names)] for k in range(n)))
        return t
    if op == 6:  # a signal expression: deep `not`, long `or`/`and` chains, deep parentheses
        holders = [n for n in t.iter_subtrees() if str(n.data) in EXPR_PARENTS]
        if holders:
            h = draw(st.sampled_from(holders))
            s = draw(st.sampled_from(sigs))
            n = draw(st.integers(1, 10) | st.integers(60, 500))
            form = draw(st.integers(0, 3))
            text = [
                "not " * n + s,
                " or ".join([s] * n),
                " and ".join(f"not {s}" for _ in range(n)),
                "(" * n + s + ")" * n,
            ][form]
            h.children[EXPR_PARENTS[str(h.data)]] = raw(text)
        return t
    if op == 7:  # a name, number or path token replaced
        tokens = [x for n in t.iter_subtrees() for x in n.children if isinstance(x, Token)]
        tokens = [x for x in tokens if x.type in ("NAME", "NUMBER", "STRING")]
        if tokens:
            tok = draw(st.sampled_from(tokens))
            new = draw(replacement(tok.type, sigs))
            for node in t.iter_subtrees():
                node.children = [Token(tok.type, new) if x is tok else x for x in node.children]
        return t
    decls = t.children
    if op == 8 and decls:
        del decls[draw(st.integers(0, len(decls) - 1))]
    elif op == 9 and decls:
        i = draw(st.integers(0, len(decls) - 1))
        decls.insert(draw(st.integers(0, len(decls))), copy.deepcopy(decls[i]))
    elif op == 10 and len(decls) > 1:
        i, j = draw(st.integers(0, len(decls) - 1)), draw(st.integers(0, len(decls) - 1))
        decls[i], decls[j] = decls[j], decls[i]
    elif op == 11 and blocks:  # a random statement in place of one
        b = draw(st.sampled_from(blocks))
        i = draw(st.integers(0, len(b.children) - 1))
        b.children[i] = raw(draw(random_stmt(tasks, sigs)))
    return t


def unparse_or_raw(x: object) -> str:
    return unparse(x) if isinstance(x, Tree) else str(x)


def identifiers() -> st.SearchStrategy[str]:
    return st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,12}", fullmatch=True)


def replacement(kind: str, sigs: list[str]) -> st.SearchStrategy[str]:
    if kind == "NUMBER":
        return st.sampled_from(
            ["0", "-0", "1e999", "-1e999", "1e-999", "9" * 400, ".5", "+3", "1e308"]
        ) | st.floats(allow_nan=False, allow_infinity=False).map(repr)
    if kind == "STRING":
        paths = ["../tasks/hold.toml", "../tasks/dwell.toml", "/etc/shadow", "/dev/null", ".", "", "x" * 300]
        paths += [
            "../tasks/move_joints.toml",
            "../../configs/robots/sim-ur5e.toml",
            "../missions/demo.mission",
        ]
        return st.sampled_from(paths).map(lambda p: f'"{p}"')
    return st.sampled_from(sigs + KEYWORDS) | identifiers() | st.sampled_from(UNICODE)


def random_stmt(tasks: list[str], sigs: list[str]) -> st.SearchStrategy[str]:
    s = st.sampled_from(sigs)
    t = st.sampled_from(tasks)
    return st.one_of(
        st.sampled_from(["nothing", "pause", "halt", "safe", "exit T", "exit Nowhere"]),
        s.map(lambda x: f"emit {x}"),
        s.map(lambda x: f"await immediate {x}"),
        t.map(lambda x: f"run {x}"),
        st.tuples(t, s).map(lambda p: f"PAR({p[0]} || {p[0]} || await {p[1]})"),
        st.tuples(t, s).map(lambda p: f"trap T in {p[0]}; exit T end"),
        st.tuples(t, s).map(lambda p: f"every {p[1]} do {p[0]} end"),
        st.tuples(t, s).map(lambda p: f"loop {p[0]} end"),  # instantaneous loop if the task is a name only
        st.tuples(t, s).map(lambda p: f"loop emit {p[1]} end"),
    )


@st.composite
def text_edit(draw: st.DrawFn, text: str) -> str:
    """A last, text-level edit, in one example of three: cut, insert a token, delete a span."""
    op = draw(st.integers(0, 8))
    if op < 6 or not text:
        return text
    pos = draw(st.integers(0, len(text)))
    if op == 6:
        return text[:pos]
    if op == 7:
        tok = draw(st.sampled_from(KEYWORDS + PUNCT + UNICODE) | identifiers() | st.text(max_size=5))
        return text[:pos] + f" {tok} " + text[pos:]
    return text[:pos] + text[pos + draw(st.integers(1, 40)) :]


@st.composite
def missions(draw: st.DrawFn) -> tuple[Path, str]:
    """(the seed mission's path, a mutated text of it); compile it as a file of the seed's
    directory so `from "../tasks/…"` still resolves."""
    seed = draw(st.sampled_from(SEEDS))
    t = seed_tree(seed)
    for _ in range(draw(st.integers(1, 3))):
        t = draw(mutated_tree(t))
    return seed, draw(text_edit(unparse(t)))
