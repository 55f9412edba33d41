"""A cell's log (two resources, two telemetry blocks at their own rates): a CSV per resource with
its columns named by it, one MCAP with every resource's channels and every joint on
`/joint_states`, the mission's events in each, carried on after a command daemon's death, plotted
from the MCAP; signal names by resource checked."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from orccadd.cmdd.csvlog import LogDir
from orccadd.cmdd.logsession import LogSource, TelemetryLog
from orccadd.cmdd.views import cell_selections
from orccadd.offline.plot import plot_csv, read_log
from orccadd.wire.schema import Layout, Trace
from orccadd.wire.telemetry import TelemetryBlock
from tests.cmdd.conftest import DESC, URDF, FakeLoop, decode

ARM = ["shoulder_pan_joint", "elbow_joint"]
HAND = ["finger_joint"]
ARM_PERIOD_S, HAND_PERIOD_S = 0.002, 0.004


@pytest.fixture
def blocks() -> Iterator[dict[str, FakeLoop]]:
    arm = TelemetryBlock.create(Layout(dof=2, tick_len=4096, trace_len=64), ARM_PERIOD_S)
    hand = TelemetryBlock.create(Layout(dof=1, tick_len=4096, trace_len=64), HAND_PERIOD_S)
    try:
        yield {"arm": FakeLoop(arm, ARM_PERIOD_S), "hand": FakeLoop(hand, HAND_PERIOD_S)}
    finally:
        arm.close()
        hand.close()


def start(
    logs: Path, loops: dict[str, FakeLoop], signals: list[str], joints: dict[str, list[str]]
) -> TelemetryLog:
    for loop in loops.values():
        loop.ticks(1)
    sels = cell_selections(signals, list(joints.items()))
    sources = [LogSource(r, loops[r].tel, sels[r]) for r in joints if r in sels]
    return TelemetryLog.start(
        LogDir(logs, ""), sources, sources[0].tel, "run.csv", lambda: DESC, decode, URDF, {}
    )


def csv_columns(path: Path) -> tuple[list[str], np.ndarray, list[str], dict[str, object]]:
    lines = path.read_text().splitlines()
    meta = json.loads(lines[0].removeprefix("# orccadd log "))
    columns = next(line for line in lines if not line.startswith("#")).split(",")
    rows = np.array([[float(v) for v in line.split(",")] for line in lines if line[0].isdigit()])
    events = [line for line in lines if line.startswith("# event,")]
    return columns, rows, events, meta


def test_a_csv_per_resource_at_its_rate_and_one_mcap_of_all(
    tmp_path: Path, blocks: dict[str, FakeLoop]
) -> None:
    logs = tmp_path / "logs"
    rec = start(logs, blocks, ["q", "hand/tau", "wake_us"], {"arm": ARM, "hand": HAND})
    blocks["arm"].ticks(100)
    blocks["hand"].ticks(50)
    blocks["arm"].trace(Trace.EVENT, 0)  # the mission's trace: in the first resource's block
    rec.pump()
    info = rec.close()
    assert info["files"] == [str(logs / "run.arm.csv"), str(logs / "run.hand.csv")]
    assert info["rows"] == 150 and info["resources"]["hand"]["rows"] == 50
    arm_cols, arm_rows, arm_events, arm_meta = csv_columns(logs / "run.arm.csv")
    hand_cols, hand_rows, hand_events, hand_meta = csv_columns(logs / "run.hand.csv")
    assert arm_cols == ["time_s", "arm/q.shoulder_pan_joint", "arm/q.elbow_joint", "arm/wake_us"]
    assert hand_cols == ["time_s", "hand/q.finger_joint", "hand/tau.finger_joint", "hand/wake_us"]
    assert (arm_meta["resource"], hand_meta["resource"]) == ("arm", "hand")
    assert (arm_meta["period_s"], hand_meta["period_s"]) == (ARM_PERIOD_S, HAND_PERIOD_S)
    np.testing.assert_allclose(np.diff(arm_rows[:, 0]), ARM_PERIOD_S, atol=1e-9)  # each at its own rate
    np.testing.assert_allclose(np.diff(hand_rows[:, 0]), HAND_PERIOD_S, atol=1e-9)
    assert len(arm_rows) == 100 and len(hand_rows) == 50
    for events in (arm_events, hand_events):  # the mission's event in each, its own mode's
        assert [e.split(",")[3:5] for e in events] == [
            ["mode", "torque"],
            ["event", "Approach.T1.TrackingDrift"],
        ]

    with (logs / "run.mcap").open("rb") as fh:
        reader = make_reader(fh)
        counts = Counter(ch.topic for _, ch, _ in reader.iter_messages())
        fh.seek(0)
        names = {
            j["name"]
            for _, ch, m in make_reader(fh).iter_messages(topics=["/joint_states"])
            for j in json.loads(m.data)["joints"]
        }
    assert counts["/arm/q"] == 100 and counts["/hand/q"] == 50 and counts["/hand/tau"] == 50
    assert "/arm/tau" not in counts and counts["/events"] >= 1
    assert names == {*ARM, *HAND}  # every joint of the cell on the one /joint_states

    d = read_log(logs / "run.mcap")  # a panel per resource and signal, each at its own rate
    assert {"arm/q.elbow_joint", "hand/q.finger_joint", "hand/tau.finger_joint"} <= set(d.columns)
    assert d.units["hand/tau"] == "N.m" and d.units["arm/q"] == "rad"
    assert "4 plots" in plot_csv(
        logs / "run.mcap", tmp_path / "cell.png", ["arm/q", "hand/q", "hand/tau", "arm/wake_us"]
    )
    assert "3 plots" in plot_csv(logs / "run.hand.csv", tmp_path / "hand.svg", [])


def test_two_identical_arms_are_told_apart_on_joint_states(
    tmp_path: Path, blocks: dict[str, FakeLoop]
) -> None:
    """Two arms with the same joint names (one config for both): `/joint_states` names them by
    resource (`left/elbow_joint`), as ROS prefixes do."""
    twin = {
        "arm": FakeLoop(blocks["arm"].tel, ARM_PERIOD_S),
        "other": FakeLoop(blocks["hand"].tel, HAND_PERIOD_S),
    }
    rec = start(tmp_path / "logs", twin, ["q.0"], {"arm": ARM, "other": ["shoulder_pan_joint"]})
    twin["arm"].ticks(30)
    twin["other"].ticks(30)
    rec.close()
    with (tmp_path / "logs/run.mcap").open("rb") as fh:
        names = {
            j["name"]
            for _, _, m in make_reader(fh).iter_messages(topics=["/joint_states"])
            for j in json.loads(m.data)["joints"]
        }
    assert names == {"arm/shoulder_pan_joint", "elbow_joint", "other/shoulder_pan_joint"}


def test_a_cell_log_is_carried_on_by_the_next_command_daemon(
    tmp_path: Path, blocks: dict[str, FakeLoop]
) -> None:
    logs = tmp_path / "logs"
    rec = start(logs, blocks, ["q"], {"arm": ARM, "hand": HAND})
    blocks["arm"].ticks(40)
    blocks["hand"].ticks(20)
    rec.pump()
    state = dict(rec.state)  # the command daemon dies here: nothing closed
    blocks["arm"].ticks(60)  # nobody logs: the next one takes these from the rings
    blocks["hand"].ticks(30)
    joined = {"arm": (blocks["arm"].tel, ARM), "hand": (blocks["hand"].tel, HAND)}
    rec2 = TelemetryLog.resume(LogDir(logs, ""), joined, blocks["arm"].tel, state, lambda: DESC, decode, URDF)
    assert rec2.state["mcap"] == ["run.mcap", "run-2.mcap"]
    blocks["arm"].ticks(10)
    blocks["hand"].ticks(5)
    info = rec2.close()
    assert info["resources"]["arm"]["rows"] == 110 and info["resources"]["hand"]["rows"] == 55
    for name, period in (("run.arm.csv", ARM_PERIOD_S), ("run.hand.csv", HAND_PERIOD_S)):
        _, rows, _, _ = csv_columns(logs / name)
        np.testing.assert_allclose(np.diff(rows[:, 0]), period, atol=1e-9)  # no row lost, none twice


@pytest.mark.parametrize(
    ("names", "error"),
    [
        (["middle/q"], "no resource 'middle' \\(resources: arm, hand\\)"),
        (["q.wrist_9"], "no resource has joint 'wrist_9'"),
        (["hand/q.elbow_joint"], "no joint 'elbow_joint'"),
    ],
)
def test_a_signal_no_resource_has_is_refused(names: list[str], error: str) -> None:
    with pytest.raises(ValueError, match=error):
        cell_selections(names, [("arm", ARM), ("hand", HAND)])


def test_an_unnamed_joint_signal_is_the_resource_that_has_it() -> None:
    sels = cell_selections(["q.finger_joint", "arm/dq.1", "wake_us"], [("arm", ARM), ("hand", HAND)])
    assert sels["hand"].labels == ["hand/q.finger_joint", "hand/wake_us"]
    assert sels["arm"].labels == ["arm/dq.elbow_joint", "arm/wake_us"]
