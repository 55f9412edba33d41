"""Small-vector helpers of the tick path agree with numpy, NaN included."""

from __future__ import annotations

import math

import numpy as np

from orccadd.vec import clamp, clamped, max_abs, max_abs_diff, max_of, min_of, outside, within

RNG = np.random.default_rng(7)


def test_list_helpers_agree_with_numpy() -> None:
    for _ in range(200):
        a, b = RNG.normal(size=6), RNG.normal(size=6)
        lo, hi = -np.abs(RNG.normal(size=6)), np.abs(RNG.normal(size=6))
        assert max_of(a) == a.max() and min_of(a) == a.min()
        assert max_abs(a.tolist()) == np.abs(a).max()
        assert max_abs_diff(a.tolist(), b.tolist()) == np.abs(a - b).max()
        assert outside(a.tolist(), lo.tolist(), hi.tolist()) == bool(((a < lo) | (a > hi)).any())
        assert within(a.tolist(), lo.tolist(), hi.tolist()) == bool(((a >= lo) & (a <= hi)).all())
        assert clamped(a.tolist(), lo.tolist(), hi.tolist()) == np.clip(a, lo, hi).tolist()
        out = np.zeros(6)
        clamp(a, lo, hi, out)
        assert out.tolist() == np.clip(a, lo, hi).tolist()


def test_values_within_bounds_come_back_unchanged() -> None:
    a = [0.1 + 0.2, -0.3, 1e-12]  # no arithmetic on a value that needs no clamping
    assert clamped(a, [-1.0] * 3, [1.0] * 3) == a


def test_nan_is_neither_inside_nor_outside_and_stays_nan() -> None:
    # callers check finiteness themselves (PhysicalResource.read/write): NaN is not "outside"
    assert not outside([math.nan], [-1.0], [1.0])
    assert math.isnan(clamped([math.nan], [-1.0], [1.0])[0])


def test_within_finite_bounds_is_outside_or_not_finite_negated() -> None:
    """`PhysicalResource.read` trusts `within` alone when its limits are finite: it must say
    what `outside` and a finiteness test say together, for NaN and infinities too."""
    lo, hi = [-1.0, -2.0], [1.0, 2.0]
    edges = ([0.0, 0.0], [-1.0, 2.0], [1.5, 0.0], [0.0, -2.5])
    for a in (*edges, [math.nan, 0.0], [0.0, math.inf], [-math.inf, 0.0]):
        assert within(a, lo, hi) == (not outside(a, lo, hi) and all(map(math.isfinite, a)))
