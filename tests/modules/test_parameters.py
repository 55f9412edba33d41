"""A module parameter takes numbers only, of its shape, within its bounds; counts take whole numbers."""

from __future__ import annotations

import numpy as np
import pytest

from orccadd.errors import ParameterError
from orccadd.modules.base import Parameter


def vector() -> Parameter:
    return Parameter("ct", "kp", 900.0, (0.0, 1e5), "1/s^2", True, (6,))


def count() -> Parameter:
    return Parameter("watch", "ticks", 1, (1, 100000), "ticks", True, (), integer=True)


@pytest.mark.parametrize(
    ("value", "why"),
    [
        (True, "must be a number or a list of numbers"),
        ("500", "must be a number or a list of numbers"),
        ([1.0, 2.0, "3", 4.0, 5.0, 6.0], "must be a number or a list of numbers"),
        ([1.0, True, 3.0, 4.0, 5.0, 6.0], "must be a number or a list of numbers"),
        ([[1.0] * 6], "must be a number or a list of numbers"),
        ([1.0, 2.0], "must be 6 numbers"),
        (-3, r"must be in \[0, 100000\]"),
        (float("nan"), r"must be in \[0, 100000\]"),
    ],
)
def test_a_bad_value_is_refused_and_nothing_changes(value: object, why: str) -> None:
    p = vector()
    with pytest.raises(ParameterError, match=why):
        p.check(value)
    assert (p.value == 900.0).all()


def test_numbers_of_every_numeric_kind_are_taken() -> None:
    p = vector()
    assert (p.check(500) == 500.0).all()
    assert (p.check(np.float32(2.5)) == 2.5).all()
    assert (p.check(np.arange(6)) == np.arange(6)).all()


def test_a_count_is_a_whole_number_not_truncated() -> None:
    p = count()
    assert p.check(3) == 3.0
    assert p.check(4.0) == 4.0
    with pytest.raises(ParameterError, match=r"\(=2.5\) must be a whole number"):
        p.check(2.5)


def test_a_position_per_joint_takes_one_number_per_joint_never_one_for_all() -> None:
    """`tune Approach.traj.target_rad 0.1` sent all six joints to 0.1 rad: refused; a gain still
    takes one number for every joint."""
    target = Parameter("traj", "target_rad", [0.0] * 6, (-3.0, 3.0), "rad", True, (6,), per_joint=True)
    with pytest.raises(ParameterError, match="must be 6 numbers, one per joint: one number would send every"):
        target.check(0.1)
    assert (target.check([0.1] * 6) == 0.1).all()
    assert (vector().check(500) == 500.0).all()
