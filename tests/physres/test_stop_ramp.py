"""The safe stop's ramp (simulated time): every joint slows together at the deceleration."""

from __future__ import annotations

import pytest

from orccadd.physres.stop_ramp import StopRamp


def test_the_fastest_joint_stops_at_the_deceleration_and_the_path_is_kept() -> None:
    r = StopRamp(3)
    r.start([0.0, 1.0, 2.0], [2.0, -1.0, 0.0], 10.0)
    t, decel = 10.0, 4.0
    while not r.done:
        t += 0.005
        r.step(t, decel)
        assert r.dq_rad_s[1] == pytest.approx(-0.5 * r.dq_rad_s[0])  # proportions kept
    assert t - 10.0 == pytest.approx(2.0 / decel, abs=0.006)
    assert r.q_rad[0] == pytest.approx(2.0**2 / (2 * decel), abs=1e-3)  # v^2 / 2a
    assert r.q_rad[1] == pytest.approx(1.0 - 0.5 * 2.0**2 / (2 * decel), abs=1e-3)
    assert r.q_rad[2] == 2.0
    q = list(r.q_rad)
    r.step(t + 1.0, decel)
    assert r.q_rad == q and r.ddq_rad_s2 == [0.0, 0.0, 0.0]


def test_hold_stands_still() -> None:
    r = StopRamp(2)
    r.hold([0.3, -0.2], 0.0)
    assert r.done
    r.step(0.1, 5.0)
    assert r.q_rad == [0.3, -0.2]
