"""The telemetry record layout: named slices, no offset arithmetic elsewhere."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.wire.schema import TICK_VECTORS, T, TickLayout


def test_the_tick_layout_names_every_column_once() -> None:
    at = TickLayout(3)
    cols = [c for v in TICK_VECTORS for c in range(at.width)[at.vector(v)]]
    assert cols == list(range(len(T), at.width))  # the vectors follow the scalars, none overlap
    assert (at.q, at.cmd) == (at.vector("q"), at.vector("cmd"))
    assert at.column("tau", 2) == len(T) + 2 * 3 + 2
    rec = np.arange(at.width, dtype=float)
    assert rec[at.dq].tolist() == [len(T) + 3.0, len(T) + 4.0, len(T) + 5.0]
    with pytest.raises(IndexError):
        at.column("q", 3)


def test_the_resources_own_signals_follow_the_joint_vectors() -> None:
    plain, at = TickLayout(3), TickLayout(3, [("wrench", 6), ("speed_scaling", 1)])
    assert (at.q, at.dq, at.tau, at.cmd) == (plain.q, plain.dq, plain.tau, plain.cmd)  # unmoved
    assert at.vector("wrench") == slice(plain.width, plain.width + 6)
    assert at.vector("speed_scaling") == slice(plain.width + 6, plain.width + 7)
    assert at.width == plain.width + 7
    with pytest.raises(ValueError, match="not in the tick record"):
        at.vector("features")
    with pytest.raises(ValueError, match="takes the name of a tick field"):
        TickLayout(3, [("q", 2)])
