"""The mission's `property` lines as Promela assertions, shared by both spin exports.

Each export says how an atom reads in its model (`Atom`): `active(T)`, `start(T)`, `stop(T)`, a
signal; `pre(S)` is a variable of its own, S's value set after the instant's checks. Evaluated once
per instant, after it (like the verifier's observers, on transitions):

- `never C`: `C` does not hold in any instant;
- `A and B alternate`: a two-state observer (A first; an instant with both counts as B then A);
- `A -> eventually B` is not exported: "B can still happen" is a branching-time property, outside
  what spin's safety search (or LTL) states; the verifier keeps it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from orccadd.automaton.language import ast as A
from orccadd.automaton.language.program import Program
from orccadd.automaton.promela.spin import prop_bit
from orccadd.errors import OrccaddError

# What an export can assert: the two built-in checks and the mission's own property lines.
PROPERTIES = ("safety", "conflicts", "properties")

Atom = Callable[[A.SigRef | A.Fn], str]


def check_properties(properties: tuple[str, ...]) -> None:
    unknown = [p for p in properties if p not in PROPERTIES]
    if unknown:
        raise OrccaddError(
            f"unknown property {', '.join(map(repr, unknown))} (choose from {', '.join(PROPERTIES)})"
        )


def expr(e: A.SigExpr, atom: Atom) -> str:
    if isinstance(e, A.SigRef | A.Fn):
        return atom(e)
    if isinstance(e, A.Not):
        return f"!{expr(e.item, atom)}"
    sep = " && " if isinstance(e, A.And) else " || "
    return "(" + sep.join(expr(i, atom) for i in e.items) + ")"


@dataclass
class PropCode:
    decls: list[str] = field(default_factory=list)  # global declarations
    checks: list[str] = field(default_factory=list)  # statements run at the end of each instant
    skipped: list[str] = field(default_factory=list)  # properties left to the verifier, and why


def encode_properties(p: Program, atom: Atom) -> PropCode:
    out = PropCode()
    pres: dict[str, str] = {}  # `pre(S)`: S's value in the instant before, one variable per signal

    def with_pre(e: A.SigRef | A.Fn) -> str:
        if isinstance(e, A.Fn) and e.fn == "pre":
            if e.arg not in pres:
                pres[e.arg] = f"pre{len(pres)}"
                out.decls.append(f"bit {pres[e.arg]};  /* pre({e.arg}): 0 before the first instant */")
            return pres[e.arg]
        return atom(e)

    for i, prop in enumerate(p.properties):
        bit = prop_bit(i, prop.name)
        try:
            a = expr(prop.a, with_pre)
            b = expr(prop.b, with_pre) if prop.b is not None else ""
        except OrccaddError as e:
            raise OrccaddError(f"property {prop.name} (line {prop.loc.line}): {e}") from None
        if prop.kind == "never":
            out.decls.append(f"bit {bit} = 1;  /* never {A.show(prop.a)} */")
            out.checks.append(f"{bit} = !{a}; assert({bit}); {bit} = 1;")
        elif prop.kind == "alternate":
            obs = f"obs{i}"
            out.decls.append(
                f"bit {bit} = 1; bit {obs};  /* {A.show(prop.a)} and {A.show(prop.b or prop.a)} alternate */"
            )
            out.checks += [
                f"{bit} = !(({obs} == 0 && {b}) || ({obs} == 1 && {a} && !{b}));",
                f"assert({bit}); {bit} = 1;",
                f"{obs} = ({a} -> 1 : ({b} -> 0 : {obs}));",
            ]
        else:
            out.skipped.append(f"{prop.name} (`-> eventually`: a branching-time property, left to check)")
    for name, var in pres.items():  # after every check of the instant: what the next one reads
        out.checks.append(f"{var} = {atom(A.SigRef(name, A.Loc(p.file, 0, 0)))};")
    return out


def exported_checks(p: Program, properties: tuple[str, ...]) -> list[str]:
    """The verifier's names of the checks a model asserts ("safety", "property NeverBoth", ...)."""
    names: list[str] = [c for c in ("safety", "conflicts") if c in properties]
    if "properties" in properties:
        names += [f"property {q.name}" for q in p.properties if q.kind in ("never", "alternate")]
    return names
