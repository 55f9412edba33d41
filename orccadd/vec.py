"""Small-vector helpers for the tick path.

Joint vectors have 6–7 elements: numpy's cost there is all per-call overhead (0.7–0.9 µs a
ufunc hot, 1.5–4.5 µs a reduction), and it grows 2–5× when the tick runs paced, with caches cold
after each idle stretch of the period. Python's builtins on lists (`tolist()`, `map`, `max`,
`min`, `abs`) are leaner and stay lean when cold. Measured on the project's 2-core VM, the same
20 operations: numpy 12 µs hot, 24 µs median and 119 µs p99 paced at 1 kHz; on lists 9.4 µs hot,
12.6 µs median and 26 µs p99 paced. Ports stay numpy buffers (shared by wiring, no allocation);
a tick reads them with `tolist()` and computes on lists. Nothing here allocates an array.
"""

from __future__ import annotations

from operator import gt, lt, sub

import numpy as np
import numpy.typing as npt


def max_of(a: npt.NDArray[np.float64]) -> float:
    """`a.max()` for a small vector."""
    return max(a.tolist())  # type: ignore[no-any-return]


def min_of(a: npt.NDArray[np.float64]) -> float:
    """`a.min()` for a small vector."""
    return min(a.tolist())  # type: ignore[no-any-return]


def max_abs(a: list[float]) -> float:
    """max |a_i|."""
    return max(map(abs, a))


def max_abs_diff(a: list[float], b: list[float]) -> float:
    """max |a_i − b_i|."""
    return max(map(abs, map(sub, a, b)))  # type: ignore[no-any-return]


def outside(a: list[float], lo: list[float], hi: list[float]) -> bool:
    """Some a_i outside [lo_i, hi_i]."""
    return any(map(lt, a, lo)) or any(map(gt, a, hi))


def within(a: list[float], lo: list[float], hi: list[float]) -> bool:
    """Every lo_i <= a_i <= hi_i: False for a NaN, and for an infinity within finite bounds.

    A loop, not `all()` on a generator (0.92 µs) nor `outside` and a finiteness test (1.08 µs):
    0.56 µs for 12 values.
    """
    for a_i, l_i, h_i in zip(a, lo, hi):  # noqa: B905, SIM110 (see `clamped`)
        if not l_i <= a_i <= h_i:
            return False
    return True


def clamped(a: list[float], lo: list[float], hi: list[float]) -> list[float]:
    """[min(max(a_i, lo_i), hi_i)] (a NaN stays NaN: check finiteness separately).

    Conditional expressions, not min/max (0.8 µs against 1.9 µs for 6 joints); zip without
    `strict=True` in the tick path (it costs 0.3–0.7 µs a call): the vectors have the robot's
    dof by construction.
    """
    return [l_i if a_i < l_i else h_i if a_i > h_i else a_i for a_i, l_i, h_i in zip(a, lo, hi)]  # noqa: B905


def clamp(
    x: npt.NDArray[np.float64],
    lo: npt.NDArray[np.float64] | float,
    hi: npt.NDArray[np.float64] | float,
    out: npt.NDArray[np.float64],
) -> None:
    """`np.clip(x, lo, hi, out=out)` without np.clip's 4 µs wrapper."""
    np.minimum(x, hi, out=out)
    np.maximum(out, lo, out=out)


def float_view(a: npt.NDArray[np.float64]) -> memoryview[float]:
    """`a`'s memory as a memoryview (made once, outside the tick): a copy between two of them,
    `view_a[:] = view_b`, costs ~0.07 µs against numpy's ~0.18 µs for `a[:] = b` (6 joints)."""
    return memoryview(a)  # type: ignore[arg-type]
