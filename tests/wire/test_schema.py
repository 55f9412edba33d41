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
