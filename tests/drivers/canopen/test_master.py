"""Pure parts of the CANopen master (the cyclic exchange is tested against the drive simulator)."""

from __future__ import annotations

import pytest

from orccadd.drivers.canopen.startup import interpolation_time_period


@pytest.mark.parametrize(
    ("period_s", "encoded"),
    [(0.002, (2, -3)), (0.004, (4, -3)), (0.001, (1, -3)), (0.0005, (5, -4)), (0.00025, (25, -5))],
)
def test_interpolation_time_period(period_s: float, encoded: tuple[int, int]) -> None:
    assert interpolation_time_period(period_s) == encoded


def test_a_period_without_an_encoding_is_refused() -> None:
    with pytest.raises(ValueError, match="0x60C2"):
        interpolation_time_period(1 / 3000)
