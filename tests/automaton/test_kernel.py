"""The kernel's terms: a sequence's residuals share the sequence as written (a state of a long
sequence costs O(1)), and are equal, hashed and `mentions`-ed as the sequence they stand for
(checked against the same residual built from scratch: the two routes agree)."""

from __future__ import annotations

from orccadd.automaton.language import kernel as K
from orccadd.automaton.language.ast import Loc

N = 200
END_MASKS = tuple(1 << t for t in range(N))  # task t ends on input bit t


def _seq() -> K.Term:
    # `await` of a different input, then a `pause`, N times: each instant one step further
    return K.seq(
        tuple(K.Await((K.IN, 1 << (i % 60)), False, Loc("t", i, 1)) if i % 2 else K.Pause() for i in range(N))
    )


def test_a_residual_shares_the_sequence_and_equals_it_built_afresh() -> None:
    t = _seq()
    assert isinstance(t, K.Seq)
    items = t.items
    residual: K.Term = t
    seen = 0
    for _ in range(N):
        r = K.Instant(inputs=(1 << 60) - 1, assumed=0, end_masks=END_MASKS)
        code, nxt = K.step(residual, r)
        if code != K.PAUSED:
            break
        residual = K.settle(nxt)
        if isinstance(residual, K.Seq):
            seen += 1
            assert residual.items is items  # shared, not copied
            fresh = K.seq((residual.first, *items[residual.start + 1 :]))
            assert fresh == residual and hash(fresh) == hash(residual) and fresh.items is not items
            assert K.mentions(residual, END_MASKS) == _mentions_by_walking(fresh)
            assert K.children(residual) == K.children(fresh)
    assert seen > N // 3


def _mentions_by_walking(t: K.Term) -> tuple[int, int]:
    """`mentions` of a sequence item by item (the definition, without the shared suffixes)."""
    assert isinstance(t, K.Seq)
    ins = ints = 0
    for item in t.parts():
        a, b = K.mentions(item, END_MASKS)
        ins, ints = ins | a, ints | b
    return ins, ints


def test_sequences_of_equal_items_are_equal_whatever_tuple_holds_them() -> None:
    a, b = _seq(), _seq()
    assert a == b and hash(a) == hash(b)
    assert isinstance(a, K.Seq) and isinstance(b, K.Seq) and a.items is not b.items
    assert K.seq((K.Pause(), a)) == K.seq((K.Pause(), *a.parts()))  # flat either way
