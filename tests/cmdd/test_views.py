"""Signal selections (`orccadd.cmdd.views.SignalSelection`): what `monitor` and `log` sample."""

from __future__ import annotations

import pytest

from orccadd.cmdd.views import SignalSelection
from orccadd.wire.schema import TickLayout

JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]


def test_a_signal_named_many_times_is_sampled_once() -> None:
    """12,000 × `q` (72,000 columns) stalled the command daemon and filled the disk at 6 GB in six
    minutes: a selection is never wider than the tick record."""
    sel = SignalSelection(["q"] * 12_000 + ["q.0", "q.elbow_joint", "tau", "wake_us", "wake_us"], JOINTS)
    assert sel.labels == [*(f"q.{j}" for j in JOINTS), *(f"tau.{j}" for j in JOINTS), "wake_us"]
    assert len(set(sel.cols)) == len(sel.cols)


@pytest.mark.parametrize("name", ["q.\u0663", "q.\uff13", "q.\u00b3", "q.6", "q.-1", "q. 1"])
def test_a_joint_index_is_ascii_digits_within_the_arm(name: str) -> None:
    with pytest.raises(ValueError, match="no joint"):
        SignalSelection([name], JOINTS)


OWN = [{"name": "wrench", "size": 6, "unit": "N|N.m"}, {"name": "speed_scaling", "size": 1, "unit": "1"}]


def test_the_resources_own_signals_are_selected_by_name_and_index() -> None:
    sel = SignalSelection(["wrench", "speed_scaling", "wrench.2"], JOINTS, "", OWN)
    assert sel.labels == [*(f"wrench.{k}" for k in range(6)), "speed_scaling"]
    first = TickLayout(6).width  # after the joint vectors
    assert sel.cols == list(range(first, first + 7))
    assert sel.units == {"wrench": "N|N.m", "speed_scaling": "1"}
    with pytest.raises(ValueError, match=r"wrench has 6 values \(0..5\)"):
        SignalSelection(["wrench.6"], JOINTS, "", OWN)
    with pytest.raises(ValueError, match="unknown signal 'wrench'"):
        SignalSelection(["wrench"], JOINTS)  # a resource without one
