"""Constructive causality (Berry, *The Constructive Semantics of Pure Esterel*, as Esterel v5 and
every Esterel tool since): an internal signal is present in an instant when the program *must*
emit it, absent when it *cannot*, and a program is accepted only if every signal it tests in an
instant gets its status this way, never by guessing one that then justifies itself.

`analyse` runs one instant of a kernel term in three-valued logic: each internal signal present,
absent or not known yet (⊥). A test of a ⊥ signal decides nothing: what follows it *can* happen
(its emissions and completion codes count in `can`), nothing of it *must* (`must`). `establish`
iterates: what must be emitted becomes present, what cannot becomes absent, until nothing moves.

    present X then emit X else emit X end      X tested while ⊥: no emission is certain, X stays
                                               ⊥ — refused (its one consistent status, present,
                                               justifies itself)
    present X then emit O end; emit X          the test must end before `emit X` is reached, and
                                               it cannot end while X is ⊥ — refused
    emit X; present X then emit O end          X must be emitted: present; O emitted — accepted

The compiler keeps its search for the consistent statuses (`compiler.resolve`), then requires
them established here; a non-constructive instant is refused where the mission reaches it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from orccadd.automaton.language import kernel as K

Codes = frozenset[int]
_DONE: Codes = frozenset((K.DONE,))
_PAUSED: Codes = frozenset((K.PAUSED,))
_EITHER: Codes = frozenset((K.DONE, K.PAUSED))


@dataclass(frozen=True)
class Env:
    """What an instant knows: the inputs, the internal signals established so far (`present`,
    `absent`; the others ⊥), `pre(S)`'s values and, in a network's context, the par's code."""

    inputs: int
    present: int
    absent: int
    prev_in: int = 0
    prev_int: int = 0
    end_masks: tuple[int, ...] = ()
    hole_code: int = K.PAUSED


@dataclass(frozen=True)
class Outcome:
    """One instant of a term in three-valued logic: the signals it must emit and those it can, the
    completion code it must end with (None: not known) and those it can."""

    must: int
    can: int
    must_code: int | None
    can_codes: Codes


_NOTHING = Outcome(0, 0, K.DONE, _DONE)
_PAUSE = Outcome(0, 0, K.PAUSED, _PAUSED)


def test(c: K.Cond, env: Env) -> bool | None:
    """A condition's value, None while it depends on a ⊥ signal (`and`/`or` decided by one side
    when that side decides them)."""
    op = c[0]
    if op == K.IN:
        return (env.inputs & int(c[1])) != 0
    if op == K.INT:
        bits = int(c[1])
        if env.present & bits:
            return True
        return False if bits & ~env.absent == 0 else None
    if op == K.AND:
        a, b = test(c[1], env), test(c[2], env)
        if a is False or b is False:
            return False
        return True if a and b else None
    if op == K.OR:
        a, b = test(c[1], env), test(c[2], env)
        if a or b:
            return True
        return False if a is False and b is False else None
    if op == K.NOT:
        v = test(c[1], env)
        return None if v is None else not v
    if op == K.PIN:
        return (env.prev_in & int(c[1])) != 0
    if op == K.PINT:
        return (env.prev_int & int(c[1])) != 0
    return True


def _unknown(*parts: Outcome, codes: Codes = frozenset()) -> Outcome:
    """Several outcomes, any of which can happen, none must."""
    can, out = 0, set(codes)
    for o in parts:
        can |= o.can
        out |= o.can_codes
    return Outcome(0, can, None, frozenset(out))


def _recode(o: Outcome, old: int, new: int) -> Outcome:
    codes = frozenset(new if k == old else k for k in o.can_codes)
    return Outcome(o.must, o.can, new if o.must_code == old else o.must_code, codes)


def analyse(t: K.Term | None, env: Env) -> Outcome:
    """One instant of `t` (as `kernel.step` takes it) in three-valued logic."""
    if t is None or isinstance(t, K.Nothing):
        return _NOTHING
    if isinstance(t, K.Emit):
        return Outcome(t.bit, t.bit, K.DONE, _DONE)
    if isinstance(t, K.Pause | K.Halt | K.Run):
        return _PAUSE
    if isinstance(t, K.Running | K.Started):
        return _NOTHING if env.inputs & env.end_masks[t.task] else _PAUSE
    if isinstance(t, K.Exit):
        return Outcome(0, 0, t.code, frozenset((t.code,)))
    if isinstance(t, K.Hole):
        return Outcome(0, 0, env.hole_code, frozenset((env.hole_code,)))
    if isinstance(t, K.Present):
        v = test(t.cond, env)
        if v is None:
            return _unknown(analyse(t.then, env), analyse(t.orelse, env))
        return analyse(t.then if v else t.orelse, env)
    if isinstance(t, K.Await):
        if not t.armed:
            return _PAUSE
        v = test(t.cond, env)
        return Outcome(0, 0, None, _EITHER) if v is None else (_NOTHING if v else _PAUSE)
    if isinstance(t, K.Seq):
        return _seq(t, env)
    if isinstance(t, K.Par):
        return _par(t, env)
    if isinstance(t, K.Loop):
        o = analyse(t.body, env)  # a body that ends at once: `step` refuses the loop itself
        return Outcome(o.must, o.can, None if o.must_code == K.DONE else o.must_code, o.can_codes - _DONE)
    if isinstance(t, K.Trap):
        return _recode(analyse(t.body, env), t.code, K.DONE)
    if isinstance(t, K.Abort):
        return _abort(t, env)
    if isinstance(t, K.Suspend):
        v = test(t.cond, env) if t.armed else False
        if v:
            return _PAUSE
        body = analyse(t.body, env)
        return body if v is False else _unknown(body, codes=_PAUSED)
    if isinstance(t, K.Handle):
        return _handle(t, env)
    raise TypeError(f"not a kernel term: {t!r}")


def _seq(t: K.Seq, env: Env) -> Outcome:
    must, can, codes = 0, 0, _DONE
    must_code: int | None = K.DONE  # the empty prefix ends at once
    for item in (t.first, *t.items[t.start + 1 :]):  # the current item as it stands, then the rest
        if K.DONE not in codes:
            break
        o = analyse(item, env)
        can |= o.can
        if must_code == K.DONE:  # the prefix must end: this item must be reached
            must |= o.must
            must_code = o.must_code
        else:
            must_code = None
        codes = (codes - _DONE) | o.can_codes
    return Outcome(must, can, must_code, codes)


def _par(t: K.Par, env: Env) -> Outcome:
    must = can = 0
    must_code: int | None = K.DONE
    codes: set[int] = {K.DONE}
    for b in t.branches:
        o = analyse(b, env)
        must |= o.must
        can |= o.can
        must_code = None if must_code is None or o.must_code is None else max(must_code, o.must_code)
        codes = {max(a, k) for a in codes for k in o.can_codes}
    return Outcome(must, can, must_code, frozenset(codes))


def _abort(t: K.Abort, env: Env) -> Outcome:
    if t.armed and not t.weak:
        v = test(t.cond, env)
        if v:
            return _NOTHING
        body = analyse(t.body, env)
        return body if v is False else _unknown(body, codes=_DONE)
    body = analyse(t.body, env)
    if not (t.armed and t.weak) or K.PAUSED not in body.can_codes:
        return body
    v = test(t.cond, env)  # a weak abort: the body reacts, then the condition ends it if paused
    if v is False:
        return body
    if v:
        return _recode(body, K.PAUSED, K.DONE)
    must_code = None if body.must_code == K.PAUSED else body.must_code
    return Outcome(body.must, body.can, must_code, body.can_codes | _DONE)


def _handle(t: K.Handle, env: Env) -> Outcome:
    seen: list[Outcome] = []  # handlers that can run, while an earlier condition is not known
    for cond, handler in zip(t.conds, t.handlers, strict=True):
        v = test(cond, env)
        if v is False:
            continue
        if v and not seen:
            return analyse(handler, env)
        seen.append(analyse(handler, env))
        if v:
            return _unknown(*seen)
    body = analyse(t.body, env)
    return _unknown(*seen, body) if seen else body


def establish(tested: int, outcome_of: Callable[[int, int], tuple[int, int]]) -> tuple[int, int]:
    """The statuses constructive semantics establishes among the internal signals `tested`:
    (present, absent), iterated from all ⊥; `outcome_of(present, absent)` gives (must, can)."""
    present = absent = 0
    while True:
        must, can = outcome_of(present, absent)
        new_present = must & tested & ~present
        new_absent = tested & ~can & ~absent & ~present
        if not new_present and not new_absent:
            return present, absent
        present |= new_present
        absent |= new_absent
