"""`orccadctl replay RUN.mcap` on real runs: a daemon on the simulated arm runs
demo_position.mission logged the ordinary way (`log start`, no signal names), once as it is and
once with Reach's speed tuned during the run; replay re-runs the recorded measurements through the
same tasks offline. Identical where nothing changed; a changed gain names the first divergent tick."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from orccadd.cli import orccadctl_main
from tests.daemon.conftest import ROOT, Daemon, start_daemon
from tests.offline.runs import logged_run

MISSION = str(ROOT / "configs/missions/demo_position.mission")


@dataclass(frozen=True)
class Runs:
    plain: Path  # demo_position as it is
    tuned: Path  # Reach.traj.speed_scale tuned to 0.6 while the log runs
    few: Path  # logged with q and cmd only


def _run(d: Daemon, out: Path, *signals: str, tune: tuple[str, str] | None = None) -> Path:
    return logged_run(d, MISSION, out, *signals, tune=tune)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runs]:
    tmp = tmp_path_factory.mktemp("replay")
    d = start_daemon(tmp)
    try:
        plain = _run(d, tmp / "plain.csv")
        tuned = _run(d, tmp / "tuned.csv", tune=("Reach.traj.speed_scale", "0.6"))
        few = _run(d, tmp / "few.csv", "q", "cmd")
    finally:
        d.stop()
    yield Runs(plain, tuned, few)


def replay(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = orccadctl_main(["replay", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_a_run_replays_to_the_same_commands_bit_for_bit(
    runs: Runs, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = replay(capsys, str(runs.plain))
    assert code == 0, out + err
    assert "verdict: identical" in out and "bit for bit" in out
    code, out, _ = replay(capsys, "--json", str(runs.plain))
    rep = json.loads(out)
    assert code == 0 and rep["identical"]
    assert [t["task"] for t in rep["tasks"]] == ["Home", "Reach", "Back"]
    assert all(t["ticks"] > 50 and t["max_diff"] == 0 for t in rep["tasks"])


def test_a_changed_gain_names_the_first_divergent_tick(
    runs: Runs, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = replay(capsys, "--json", str(runs.plain), "--set", "Reach.traj.speed_scale=0.6")
    assert code == 1, out + err
    rep = json.loads(out)
    home, reach, back = rep["tasks"]
    assert home["divergence"] is None and back["divergence"] is None  # the others replay alike
    d = reach["divergence"]
    assert d["signal"].startswith("cmd.") and d["by"] > 0 and d["run"] != d["replay"]
    assert reach["first_tick"] <= d["tick"] < reach["first_tick"] + 5  # from its first ticks on
    assert reach["differing_ticks"] > reach["ticks"] // 2 and reach["max_diff"] > 0.01
    code, out, _ = replay(capsys, str(runs.plain), "--set", "Reach.traj.speed_scale=0.6")
    assert code == 1
    assert f"verdict: diverged: first at tick {d['tick']}, task Reach, {d['signal']}" in out
    # a tolerance wide enough takes it as the same; --task replays that task alone
    assert replay(capsys, str(runs.plain), "--set", "Reach.traj.speed_scale=0.6", "--tol", "1")[0] == 0
    faster = ("--set", "Reach.traj.speed_scale=0.6")
    code, out, _ = replay(capsys, "--json", str(runs.plain), "--task", "Home", *faster)
    assert code == 0 and [t["task"] for t in json.loads(out)["tasks"]] == ["Home"]


def test_the_runs_tunes_are_applied_at_their_ticks(runs: Runs, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = replay(capsys, str(runs.tuned))
    assert code == 0, out + err
    assert "the run's tune Reach.traj.speed_scale = 0.6 applied at tick" in out
    # the same run replayed with the file's speed instead: Reach differs, and says so
    code, out, _ = replay(capsys, str(runs.tuned), "--set", "Reach.traj.speed_scale=0.4")
    assert code == 1 and "--set overrides it" in out and "task Reach" in out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--task", "Nowhere"], "the mission has no task 'Nowhere' (its tasks: Home, Reach, Back)"),
        (["--set", "Reach.traj.speed_scale"], "TASK.MODULE.PARAM=VALUE"),
        (["--set", "Reach.traj.speed_scale=fast"], "TASK.MODULE.PARAM=VALUE"),
        (["--set", "Reach.traj.speed_scale=7"], "speed_scale"),
        (["--set", "Reach.nothing.k=1"], "task Reach has no parameter 'nothing.k'"),
        (["--tol", "-1"], "--tol -1.0: a difference, 0 or more"),
        (["--config", "/nonexistent/robot.toml"], "/nonexistent/robot.toml"),
    ],
)
def test_bad_requests_are_refused_in_words(
    runs: Runs, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    code, out, err = replay(capsys, str(runs.plain), *argv)
    assert code == 2 and out == "" and words in err, err


def test_logs_that_cannot_be_replayed_are_refused_in_words(
    runs: Runs, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, _, err = replay(capsys, str(runs.few))
    assert code == 2 and "the log lacks t_s, task, wrote, mode, status, dq, tau" in err
    cut = tmp_path / "cut.mcap"
    data = runs.plain.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    code, _, err = replay(capsys, str(cut))
    assert code == 2 and f"{cut}: not a readable MCAP log: truncated or corrupted" in err
    code, _, err = replay(capsys, str(runs.plain.with_suffix(".csv")))
    assert code == 2 and "not an MCAP file" in err
    code, _, err = replay(capsys, str(tmp_path / "none.mcap"))
    assert code == 2 and "cannot be read" in err


def test_the_run_record_has_the_mission_its_parameters_every_tune_and_the_result(runs: Runs) -> None:
    from mcap.reader import make_reader

    with runs.tuned.open("rb") as fh:
        records = [(m.name, dict(m.metadata)) for m in make_reader(fh).iter_metadata()]
    names = [n for n, _ in records]
    assert names[0] == "orccadd.log" and "orccadd.mission" in names and names[-1] == "orccadd.log.end"
    mission = next(r for n, r in records if n == "orccadd.mission")
    assert mission["name"] == "PositionDemo" and "task Reach on arm" in mission["mission"]
    assert json.loads(mission["tasks"]) == ["Hold", "Home", "Reach", "Back"]
    assert json.loads(mission["parameters"])["Reach"]["traj.speed_scale"] == 0.4  # as loaded
    tunes = [r for n, r in records if n == "orccadd.tune"]
    assert len(tunes) == 1 and tunes[0]["tune"].startswith("(operator) Reach.traj.speed_scale: 0.4 → 0.6")
    assert dict(records)["orccadd.log.end"]["result"] == "success"


def _rewritten(src: Path, out: Path, drop: str = "", prefix: str = "") -> Path:
    """`src` copied with the metadata records named `drop` left out, and every signal's name
    given the resource prefix `prefix` (as a station's log names them: `left/q`)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with src.open("rb") as fh, out.open("wb") as dst:
        w = Writer(dst)
        w.start()
        r = make_reader(fh)
        for m in r.iter_metadata():
            if m.name != drop:
                w.add_metadata(m.name, m.metadata)
        ids: dict[int, int] = {}
        for schema, ch, msg in r.iter_messages(log_time_order=False):
            if schema is None:
                continue
            if ch.id not in ids:
                meta = dict(ch.metadata)
                if prefix and "signal" in meta:
                    meta["signal"] = prefix + meta["signal"]
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[ch.id] = w.register_channel(ch.topic, ch.message_encoding, sid, meta)
            w.add_message(ids[ch.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        w.finish()  # type: ignore[no-untyped-call]
    return out


def test_a_log_without_its_mission_or_of_a_station_is_refused_in_words(
    runs: Runs, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # the copy itself replays: what the two others lack is all that differs
    same = _rewritten(runs.plain, tmp_path / "same.mcap")
    assert replay(capsys, str(same))[0] == 0
    bare = _rewritten(runs.plain, tmp_path / "bare.mcap", drop="orccadd.mission")
    code, _, err = replay(capsys, str(bare))
    assert code == 2 and "the log carries no mission" in err, err
    station = _rewritten(runs.plain, tmp_path / "station.mcap", prefix="left/")
    code, _, err = replay(capsys, str(station))
    assert code == 2 and "a station's log (signal left/" in err and "one-resource robot's run" in err, err
