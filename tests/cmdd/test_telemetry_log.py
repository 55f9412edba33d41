"""A log from a short telemetry run: the CSV (time from the log's start, its header, the events
among the rows) and the MCAP beside it (channels with units, events, the URDF), read back with
numpy and mcap's own reader; carried on after a command daemon's death; ended by a write error."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from orccadd.cmdd.csvlog import HEADER_LINES, LogDir
from orccadd.cmdd.logsession import LogSource, TelemetryLog
from orccadd.cmdd.mcaplog import seal
from orccadd.cmdd.urdf import urdf_path
from orccadd.cmdd.views import SignalSelection
from orccadd.config.robot import read_robot_config
from orccadd.wire.schema import CommandMode, OperatorAction, Trace, TuneRecord
from orccadd.wire.telemetry import TelemetryBlock
from tests.cmdd.conftest import DESC, PERIOD_S, ROOT, URDF, FakeLoop, decode

SIGNALS = ["q", "tau", "cmd", "wake_us", "task"]


def start(tmp_path: Path, tel: TelemetryBlock, name: str = "run.csv") -> TelemetryLog:
    if not int(tel.header[4]):  # H.TICK_HEAD
        FakeLoop(tel).ticks(1)
    sel = SignalSelection(SIGNALS, DESC["joints"])
    return TelemetryLog.start(
        LogDir(tmp_path / "logs", ""), [LogSource("", tel, sel)], tel, name, lambda: DESC, decode, URDF, {}
    )


def read_csv(path: Path) -> tuple[list[str], list[str], np.ndarray, list[list[str]]]:
    """The comment lines before the columns, the columns, the rows, the event lines."""
    lines = path.read_text().splitlines()
    header = lines[:HEADER_LINES]
    columns = lines[HEADER_LINES].split(",")
    events = [r for r in csv.reader(lines[HEADER_LINES + 1 :]) if r[0] == "# event"]
    rows = np.loadtxt(path, delimiter=",", skiprows=HEADER_LINES + 1, ndmin=2)  # '#' lines skipped
    return header, columns, rows, events


def mcap_messages(path: Path) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    with path.open("rb") as fh:
        for _, channel, msg in make_reader(fh).iter_messages():
            out.setdefault(channel.topic, []).append((msg.log_time, json.loads(msg.data)))
    return out


def test_a_log_writes_csv_and_mcap_with_units_events_and_the_robot(tmp_path: Path, loop: FakeLoop) -> None:
    loop.ticks(10)
    rec = start(tmp_path, loop.tel)
    loop.ticks(20)
    loop.trace(Trace.COMMAND, OperatorAction.START)
    loop.trace(Trace.INSTANT, inputs=(0,), actions=(0,))  # start -> Approach
    rec.pump()
    loop.mode = CommandMode.POSITION
    loop.ticks(30)
    loop.trace(Trace.EVENT, 1)  # Approach.T3.LimitViolation
    loop.trace(Trace.FAULT, 1)  # the safe stop's cause, number 1 (DESC's "faults")
    info = rec.close()
    assert info["rows"] == 50 and info["lost"] == 0 and info["urdf"] == str(URDF)

    header, columns, rows, events = read_csv(tmp_path / "logs/run.csv")
    meta = json.loads(header[0].removeprefix("# orccadd log "))
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z", meta["start_utc"])
    assert meta["origin_t_s"] == loop.t_s(10) and meta["origin_tick"] == 10  # the tick before the log
    units = json.loads(header[1].removeprefix("# units "))
    assert (
        units["time_s"] == "s" and units["q"] == "rad" and units["tau"] == "N.m" and units["wake_us"] == "us"
    )
    assert columns[:3] == ["time_s", "q.shoulder_pan_joint", "q.elbow_joint"] and rows.shape == (
        50,
        len(columns),
    )
    assert np.allclose(rows[:, 0], np.arange(1, 51) * PERIOD_S)  # seconds since the log started
    assert [(e[3], e[4]) for e in events] == [
        ("mode", "torque"),
        ("command", "start"),
        ("instant", "start"),
        ("mode", "position"),
        ("event", "Approach.T3.LimitViolation"),
        ("fault", "Approach.T3.LimitViolation"),
    ]
    assert events[-1][5] == "arm: measured position of elbow_joint 3.2 rad outside [-3.1, 3.1]"
    assert float(events[1][1]) == pytest.approx(20 * PERIOD_S)

    with (tmp_path / "logs/run.mcap").open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {f"/{s}" for s in SIGNALS} | {
            "/joint_states",
            "/events",
            "/faults",
            "/robot_description",
        }
        counts = summary.statistics.channel_message_counts  # type: ignore[union-attr]
        assert all(counts[channels[f"/{s}"].id] == 50 for s in SIGNALS)
        assert channels["/tau"].metadata["unit"] == "N.m"
        schema = json.loads(summary.schemas[channels["/q"].schema_id].data)
        assert schema["properties"]["elbow_joint"]["unit"] == "rad"
        assert summary.schemas[channels["/events"].schema_id].name == "foxglove.Log"
        assert summary.schemas[channels["/faults"].schema_id].name == "orccadd.StopCause"
        assert summary.schemas[channels["/joint_states"].schema_id].name == "foxglove.JointStates"
        [attachment] = list(reader.iter_attachments())
        assert attachment.name == "ur5e.urdf" and attachment.data == URDF.read_bytes()
        log_meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert log_meta["orccadd.log"]["start_utc"] == meta["start_utc"]
        assert log_meta["orccadd.log.end"]["rows"] == "50"
    msgs = mcap_messages(tmp_path / "logs/run.mcap")
    cmd = [m for _, m in msgs["/cmd"]]
    assert (cmd[0]["unit"], cmd[-1]["unit"]) == ("N.m", "rad") and cmd[0]["time_s"] == pytest.approx(PERIOD_S)
    assert [m["message"] for _, m in msgs["/events"]][1:3] == [
        "start (operator)",
        "start -> Approach (state 0 -> 1)",
    ]
    assert [m["level"] for _, m in msgs["/events"]][-2:] == [4, 4]  # a type 3 exception, a safe stop: errors
    [(_, cause)] = msgs["/faults"]
    assert (cause["kind"], cause["joint"], cause["n"]) == ("limit", "elbow_joint", 1)
    wall0 = msgs["/q"][0][0]  # log times: the wall clock at the start plus time_s
    assert msgs["/q"][-1][0] - wall0 == pytest.approx(49 * PERIOD_S * 1e9, abs=1e3)
    joints = msgs["/joint_states"][0][1]["joints"]
    assert [j["name"] for j in joints] == DESC["joints"] and joints[1]["effort"] == 6.0
    assert len(msgs["/joint_states"]) == 5  # 50 Hz of a 500 Hz loop


def test_a_log_outlives_its_command_daemon(tmp_path: Path, loop: FakeLoop) -> None:
    """Killed mid-write: the next command daemon carries the CSV on from its last complete row
    with the same origin, no tick twice or missing, no event twice; the MCAP in a second part,
    the first sealed (readable by any reader)."""
    logs = tmp_path / "logs"
    loop.ticks(5)
    rec = start(tmp_path, loop.tel)
    loop.ticks(40)
    loop.trace(Trace.COMMAND, OperatorAction.START)
    rec.pump()
    state = dict(rec.state)
    with (logs / "run.csv").open("a") as fh:
        fh.write("0.0999")  # the dead daemon's half row
    with (logs / "run.mcap").open("ab") as fh:
        fh.write(b"\x06\xff\xff\x00\x00\x00\x00\x00\x00half a chunk")
    loop.ticks(300)  # nobody logs
    loop.trace(Trace.EVENT, 0)
    rec2 = TelemetryLog.resume(
        LogDir(logs, ""), {"": (loop.tel, DESC["joints"])}, loop.tel, state, lambda: DESC, decode, URDF
    )
    assert rec2.state["mcap"] == ["run.mcap", "run-2.mcap"]
    loop.ticks(10)
    info = rec2.close()
    assert info["rows"] == 350 and info["resumed"] and "gap" not in info, info
    assert any("sealed" in n for n in info["notes"])

    _, _, rows, events = read_csv(logs / "run.csv")
    assert np.allclose(rows[:, 0], np.arange(1, 351) * PERIOD_S)  # same origin, every tick once
    assert [e[4] for e in events if e[3] != "mode"] == ["start", "Approach.T1.TrackingDrift"]
    part1, part2 = mcap_messages(logs / "run.mcap"), mcap_messages(logs / "run-2.mcap")
    t1 = [m["time_s"] for _, m in part1["/q"]]
    t2 = [m["time_s"] for _, m in part2["/q"]]
    assert t1 == pytest.approx(np.arange(1, 41) * PERIOD_S) and t2 == pytest.approx(
        np.arange(41, 351) * PERIOD_S
    )
    with (logs / "run-2.mcap").open("rb") as fh:
        meta = {m.name: m.metadata for m in make_reader(fh).iter_metadata()}
    assert meta["orccadd.log"]["part"] == "2" and meta["orccadd.log"]["continues"] == "run.mcap"


def test_a_write_error_ends_the_log_with_the_reason(tmp_path: Path, loop: FakeLoop) -> None:
    rec = start(tmp_path, loop.tel)
    assert rec.mcap is not None
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, rec.mcap.fh.fileno())  # the disk fills up under the MCAP file
    os.close(full)
    loop.ticks(10)
    with pytest.raises(OSError) as err:
        rec.pump()
    out = rec.abandon(err.value)
    assert "No space left on device" in out["error"] and "run.mcap" in out["error"], out


def test_only_new_files_a_name_already_taken_by_an_mcap_is_refused(tmp_path: Path, loop: FakeLoop) -> None:
    (tmp_path / "logs").mkdir(mode=0o750)
    (tmp_path / "logs/run.mcap").write_bytes(b"someone's")
    with pytest.raises(ValueError, match=r"run\.mcap already exists"):
        start(tmp_path, loop.tel)
    assert not (tmp_path / "logs/run.csv").exists()  # nothing left behind


def test_an_mcap_cut_anywhere_is_sealed_readable(tmp_path: Path, loop: FakeLoop) -> None:
    rec = start(tmp_path, loop.tel)
    for _ in range(3):
        loop.ticks(20)
        rec.pump()
    rec.close()
    whole = (tmp_path / "logs/run.mcap").read_bytes()
    found = []
    for n in [8, 9, len(whole) // 3, len(whole) // 2, len(whole) - 30, len(whole)]:
        part = tmp_path / f"cut-{n}.mcap"
        part.write_bytes(whole[:n])
        fd = os.open(part, os.O_RDWR)
        try:
            seal(fd)
        finally:
            os.close(fd)
        with part.open("rb") as fh:
            reader = make_reader(fh)
            found.append(sum(c.topic == "/q" for _, c, _ in reader.iter_messages()))
    assert found == sorted(found) and found[-2:] == [60, 60] and found[0] == 0, found  # cut in the index: all
    assert (tmp_path / f"cut-{len(whole)}.mcap").read_bytes() == whole  # a finished file is left alone


def test_a_gap_longer_than_the_ring_is_counted_and_marked_where_the_rows_resume(
    tmp_path: Path, loop: FakeLoop
) -> None:
    """A command daemon respawned after more ticks than the ring keeps: every missing tick counted
    in `lost` (before: a 2.29 s hole of 1,419 rows reported as lost=141), the gap said with its
    size in the summary and marked by an event in the CSV and the MCAP where the rows resume."""
    logs = tmp_path / "logs"
    loop.ticks(5)
    rec = start(tmp_path, loop.tel)
    loop.ticks(40)
    rec.pump()
    state = dict(rec.state)
    ring = len(loop.tel.ticks)
    loop.ticks(ring + 250)  # nobody logs for longer than the ring keeps
    rec2 = TelemetryLog.resume(
        LogDir(logs, ""), {"": (loop.tel, DESC["joints"])}, loop.tel, state, lambda: DESC, decode, URDF
    )
    loop.ticks(10)
    info = rec2.close()
    _, _, rows, events = read_csv(logs / "run.csv")
    missing = 40 + ring + 250 + 10 - len(rows)  # the gap, and 10 the ring overwrote meanwhile
    assert missing == 260 and info["lost"] == missing, (missing, info["lost"])
    assert f"250 ticks ({250 * PERIOD_S:.3f} s) lost" in info["gap"], info
    [gap] = [e for e in events if e[3] == "gap"]
    assert gap[4].startswith("250 ticks lost") and float(gap[1]) == pytest.approx(rows[40, 0])
    marks = [m for _, m in mcap_messages(logs / "run-2.mcap")["/events"] if m["name"] == "orccadd.gap"]
    assert len(marks) == 1 and marks[0]["level"] == 3  # a warning


def test_no_log_before_the_loops_first_tick(tmp_path: Path, tel: TelemetryBlock) -> None:
    sel = SignalSelection(["q"], DESC["joints"])
    with pytest.raises(ValueError, match="not ticked yet"):
        TelemetryLog.start(
            LogDir(tmp_path / "logs", ""),
            [LogSource("", tel, sel)],
            tel,
            "run.csv",
            lambda: DESC,
            decode,
            None,
            {},
        )


def test_the_robot_description_is_found_from_the_config() -> None:
    ur5e = urdf_path(read_robot_config(ROOT / "configs/robots/sim-ur5e.toml"))
    assert ur5e == (ROOT / "configs/urdf/ur5e.urdf").resolve()
    panda = urdf_path(read_robot_config(ROOT / "configs/robots/sim-panda.toml"))
    assert panda is not None and panda.name == "panda.urdf"


def test_the_csv_reads_with_the_csv_module_skipping_comments(tmp_path: Path, loop: FakeLoop) -> None:
    rec = start(tmp_path, loop.tel)
    loop.ticks(3)
    loop.trace(Trace.COMMAND, OperatorAction.HOLD)
    rec.close()
    with (tmp_path / "logs/run.csv").open(newline="") as fh:
        rows: list[dict[str, Any]] = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert len(rows) == 3 and float(rows[0]["time_s"]) == pytest.approx(PERIOD_S)
    shutil.rmtree(tmp_path / "logs")


def test_a_tune_in_the_log_names_the_parameter_its_values_and_the_tick(
    tmp_path: Path, loop: FakeLoop
) -> None:
    loop.ticks(5)
    rec = start(tmp_path, loop.tel)
    loop.ticks(10)
    # Approach (task id 1) ct.kp (index 1) element 2: 500 → 600, applied at tick 15; then the whole
    # target of 9 joints (a vector longer than the record keeps: the first 8 of 9)
    for tune in (TuneRecord(1, 1, 2, 15, [500.0], [600.0]), TuneRecord(1, 2, -1, 16, [0.0] * 9, [0.5] * 9)):
        head, values = tune.encode()
        loop.trace(Trace.COMMAND, OperatorAction.TUNE, inputs=head, actions=values)
    loop.ticks(10)
    rec.close()
    _, _, _, events = read_csv(tmp_path / "logs/run.csv")
    tunes = [e[5] for e in events if e[4] == "tune"]
    eight = "[" + ", ".join(["0.5"] * 8) + "]"
    assert tunes == [
        "(operator) Approach.ct.kp[2]: 500 → 600 (tick 15)",
        f"(operator) Approach.traj.target_rad: [{', '.join(['0'] * 8)}] → {eight} (first 8 of 9) (tick 16)",
    ]
    msgs = [m["message"] for _, m in mcap_messages(tmp_path / "logs/run.mcap")["/events"]]
    assert "tune (operator) Approach.ct.kp[2]: 500 → 600 (tick 15)" in msgs
