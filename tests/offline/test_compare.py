"""`orccadctl compare A.mcap B.mcap` on real runs: one daemon on the simulated arm runs
demo_position.mission logged twice the same way, once with Reach's speed scale tuned, and a
one-task mission of its own; the comparisons and the refusals of bad input, through orccadctl."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from orccadd.cli import orccadctl_main
from orccadd.offline.logread import CsvLogData
from orccadd.offline.runs import RunError, _instants, _windows, same_mission
from tests.daemon.conftest import ROOT, Daemon, start_daemon
from tests.offline.runs import logged_run

MISSION = str(ROOT / "configs/missions/demo_position.mission")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
ONE_TASK = f"""mission OneTask

resource arm
input Stop

task Nudge on arm from "{ROOT}/configs/tasks/move_joints_csp.toml"
  set traj.target_rad = [0.0, -0.15, -1.45, 0.0, 0.1, 0.0]
  set traj.speed_scale = 0.4
  set reached.tolerance_rad = 0.01
  post
end

main procedure Once
  handle
    do
      Nudge
    until Stop
  on fatal do
    safe
  end
end

safe procedure Acknowledge
  await Stop
end
"""


@dataclass(frozen=True)
class Runs:
    same_a: Path  # demo_position, twice alike
    same_b: Path
    tuned: Path  # demo_position with Reach.traj.speed_scale 0.6 (0.4 in the file)
    other: Path  # another mission (OneTask)


SIGNALS = ("q", "tau", "cmd", "wake_us", "compute_us")  # what compare reads, as a user would log


def _run(d: Daemon, mission: str, out: Path | None, tune: tuple[str, str] | None = None) -> Path:
    return logged_run(d, mission, out, *SIGNALS, tune=tune)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runs]:
    tmp = tmp_path_factory.mktemp("compare")
    d = start_daemon(tmp)
    try:
        _run(d, MISSION, None)  # to the mission's home pose: every run after starts from there
        same_a = _run(d, MISSION, tmp / "a.csv")
        same_b = _run(d, MISSION, tmp / "b.csv")
        tuned = _run(d, MISSION, tmp / "tuned.csv", ("Reach.traj.speed_scale", "0.6"))
        one = tmp / "one_task.mission"
        one.write_text(ONE_TASK)
        other = _run(d, str(one), tmp / "other.csv")
    finally:
        d.stop()
    yield Runs(same_a, same_b, tuned, other)


def compare(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = orccadctl_main(["compare", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_two_runs_of_one_mission_are_the_same(runs: Runs, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = compare(capsys, str(runs.same_a), str(runs.same_b))
    assert code == 0, out + err
    assert "trace: the same (4 instants" in out and "verdict: the same within the tolerances" in out
    assert "task Reach:" in out and "tracking error: q - cmd (position commands)" in out
    code, out, _ = compare(capsys, "--json", str(runs.same_a), str(runs.same_b))
    rep = json.loads(out)
    assert code == 0 and rep["verdict"] == "same" and rep["differences"] == []
    assert rep["trace"]["same"] and rep["trace"]["instants"] == [4, 4]
    if rep["mission"]["told_by"] == "metadata":  # the log's run record names its mission
        assert rep["mission"]["a"] == rep["mission"]["b"] == "PositionDemo"
    else:  # an older log: by the tasks' names
        assert rep["mission"]["told_by"] == "task names"
    assert [t["task"] for t in rep["tasks"]] == ["Home", "Reach", "Back"]
    reach = rep["tasks"][1]
    assert abs(reach["duration_s"]["diff"]) < 0.05 and reach["mode"] == ["position", "position"]
    assert set(reach["tracking"]["a"]["rms_rad"]) == {j for j in reach["cmd_diff"]["p95"]}
    assert {"wake_us", "compute_us"} <= set(reach["timing"]["a"])
    assert set(reach["timing"]["a"]["wake_us"]) == {"median", "p99", "max"}


def test_a_tuned_speed_is_reported_with_the_task_that_differs(
    runs: Runs, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    png, mcap = tmp_path / "cmp.png", tmp_path / "cmp.mcap"
    code, out, err = compare(capsys, str(runs.same_a), str(runs.tuned), "-o", str(png), "--mcap", str(mcap))
    assert code == 1, out + err
    assert "trace: the same" in out  # the same reactions, at other times
    assert "verdict: different" in out and "  - Reach: " in out
    assert png.read_bytes()[:8] == PNG_MAGIC and "3 tasks x 6 joints" in out
    with mcap.open("rb") as fh:
        topics = {c.topic for c in make_reader(fh).get_summary().channels.values()}  # type: ignore[union-attr]
    assert {"/a/q", "/b/q", "/a/cmd", "/b/cmd", "/a/events", "/b/events"} <= topics
    code, out, _ = compare(capsys, "--json", str(runs.same_a), str(runs.tuned))
    rep = json.loads(out)
    assert code == 1 and rep["verdict"] == "different"
    kinds = {(d["kind"], d["task"]) for d in rep["differences"]}
    assert ("duration", "Reach") in kinds and ("cmd", "Reach") in kinds and ("q", "Reach") in kinds
    assert not any(d["task"] in ("Home", "Back") for d in rep["differences"])  # the others alike
    reach = rep["tasks"][1]
    assert reach["duration_s"]["b"] < reach["duration_s"]["a"] - 0.1  # faster at 0.6 than 0.4
    # wide enough tolerances: the same
    wide = ["--tol-duration-s", "1", "--tol-cmd-rad", "1", "--tol-q-rad", "1"]
    assert compare(capsys, str(runs.same_a), str(runs.tuned), *wide)[0] == 0


def test_another_mission_is_refused_naming_both_files(runs: Runs, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = compare(capsys, str(runs.same_a), str(runs.other))
    assert code == 2 and out == ""
    assert str(runs.other) in err and str(runs.same_a) in err
    by_name = (
        "a run of mission OneTask" in err
        and "of PositionDemo (the missions' names in the logs' metadata)" in err
    )
    by_tasks = "two different missions" in err and "Nudge" in err and "told by the tasks' names" in err
    assert by_name or by_tasks, err
    code, out, _ = compare(capsys, "--json", str(runs.same_a), str(runs.other))
    assert code == 2 and json.loads(out)["verdict"] == "error"


def test_bad_files_are_refused_in_words(
    runs: Runs, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    text = tmp_path / "notes.mcap"
    text.write_text("not a log\n")
    csv = runs.same_a.with_suffix(".csv")
    cut = tmp_path / "cut.mcap"
    data = runs.same_a.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    cases = {
        text: "not an MCAP file",
        csv: "not an MCAP file (a CSV log? compare reads the MCAP beside it, a.mcap)",
        cut: "truncated or corrupted",
        tmp_path / "absent.mcap": "cannot be read",
        _without_events(runs.same_a, tmp_path / "no_events.mcap"): "no /events channel",
        _foreign(tmp_path / "foreign.mcap"): "without an orccadd log's signals",
    }
    for path, words in cases.items():
        code, out, err = compare(capsys, str(runs.same_a), str(path))
        assert code == 2 and out == "" and str(path) in err and words in err, (path, err)
    code, _, err = compare(capsys, "--tol-cmd-rad", "-1", str(runs.same_a), str(runs.same_b))
    assert code == 2 and "--tol-cmd-rad (=-1.0) must be a number >= 0" in err


def _without_events(src: Path, out: Path) -> Path:
    """A copy of a run's MCAP with every channel but /events."""
    with src.open("rb") as fh, out.open("wb") as dst:
        w = Writer(dst)
        w.start()
        r = make_reader(fh)
        for m in r.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        ids: dict[int, int] = {}
        for schema, ch, msg in r.iter_messages():
            if ch.topic == "/events" or schema is None:
                continue
            if ch.id not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[ch.id] = w.register_channel(ch.topic, ch.message_encoding, sid, ch.metadata)
            w.add_message(ids[ch.id], msg.log_time, msg.data, msg.publish_time)
        w.finish()  # type: ignore[no-untyped-call]
    return out


def _foreign(out: Path) -> Path:
    """An MCAP file of something else: one channel /chatter."""
    with out.open("wb") as fh:
        w = Writer(fh)
        w.start()
        ch = w.register_channel("/chatter", "json", w.register_schema("s", "jsonschema", b"{}"))
        w.add_message(ch, 1, b'{"data": "hello"}', 1)
        w.finish()  # type: ignore[no-untyped-call]
    return out


def _log(*events: tuple[float, str]) -> CsvLogData:
    """A log holding only instants (time, `inputs -> actions (state i -> j)`)."""
    import numpy as np

    names = [(t, "instant", text.split(" ", 1)[0]) for t, text in events]
    return CsvLogData(["time_s"], np.zeros((1, 1)), {}, {}, names, [text for _, text in events])


def test_instants_and_task_windows_from_the_trace() -> None:
    log = _log(
        (0.1, "(no input) -> start Home (state 0 -> 1)"),
        (0.5, "Home.done -> stop Home start Reach emit Near (state 1 -> 3)"),
        (0.9, "Reach.T2.Lost+Stop -> stop Reach start Home (state 3 -> 4)"),
        (1.2, "Tick -> (no action) (state 4 -> 4)"),
    )
    inst = _instants(Path("x.mcap"), log)
    assert [i.actions for i in inst] == [
        ("start Home",), ("stop Home", "start Reach", "emit Near"), ("stop Reach", "start Home"), ()
    ]  # fmt: skip
    assert inst[2].inputs == "Reach.T2.Lost+Stop" and (inst[2].src, inst[2].dst) == ("3", "4")
    windows = _windows(inst)
    assert [(w.key, w.start_s, w.stop_s) for w in windows] == [
        ("Home", 0.1, 0.5), ("Reach", 0.5, 0.9), ("Home#2", 0.9, None)
    ]  # fmt: skip
    with pytest.raises(RunError, match="not as orccadd writes them"):
        _instants(Path("x.mcap"), _log((0.0, "garbage")))


def test_one_mission_told_by_name_where_the_logs_carry_it() -> None:
    from orccadd.offline.runs import Run

    def run(name: str, tasks: list[str]) -> Run:
        text = " ".join(f"start {t}" for t in tasks)
        log = _log((0.0, f"(no input) -> {text} (state 0 -> 1)"))
        log.meta = {"mission": name} if name else {}
        inst = _instants(Path(f"{name or 'x'}.mcap"), log)
        return Run(Path(f"{name or 'x'}.mcap"), log, inst, _windows(inst))

    assert same_mission(run("Demo", ["A"]), run("Demo", ["B"]))[0] == "metadata"
    with pytest.raises(RunError, match="a run of mission Other, Demo.mcap of Demo"):
        same_mission(run("Demo", ["A"]), run("Other", ["A"]))
    assert same_mission(run("", ["A", "B"]), run("", ["A"]))[0] == "task names"  # B cut short
    with pytest.raises(RunError, match="two different missions"):
        same_mission(run("", ["A", "B"]), run("", ["A", "C"]))
