"""`orccadctl logs` and `fetch`: a run logged on the daemon is listed (with its mission and
result) and copied to the console chunk by chunk, each file checked by sha256; a name that is
not one of the daemon's logs, a path, and the log being written are refused."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from mcap.reader import make_reader

from orccadd import __version__
from tests.daemon.conftest import Daemon


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_logged_run_is_listed_and_fetched_whole(daemon: Daemon, tmp_path: Path) -> None:
    assert daemon.ctl("load", "demo_position").returncode == 0
    assert daemon.ctl("log", "start", "q", "tau", "--name", "run1.csv").returncode == 0
    refused = daemon.reply("fetch", name="run1.csv")
    assert not refused["ok"] and "run1.csv is being written: `orccadctl log stop` first" in refused["error"]
    p = daemon.ctl("start", "--wait")  # returns at the run's end
    assert p.returncode == 0 and p.stdout.strip().endswith("the run ended: success"), p.stdout
    assert daemon.status()["result"] == "success"
    stop = json.loads(daemon.ctl("log", "stop", "--json").stdout)["result"]
    listed = json.loads(daemon.ctl("logs", "--json").stdout)
    log = next(lg for lg in listed["logs"] if lg["name"] == "run1.csv")
    assert log["mcap"] == ["run1.mcap"] and not log["writing"] and log["start_utc"], log
    assert (log["mission"], log["result"]) == ("PositionDemo", "success"), log
    words = daemon.ctl("logs").stdout
    assert "run1.csv" in words and "run1.mcap" in words, words
    out = tmp_path / "console"
    p = daemon.ctl("fetch", "run1.csv", "-o", str(out))
    assert p.returncode == 0, p.stdout + p.stderr
    src = Path(stop["file"]).parent
    for name in ("run1.csv", "run1.mcap"):
        assert sha(out / name) == sha(src / name) and "checked" in p.stdout
    with (out / "run1.mcap").open("rb") as f:  # the run's record, as Foxglove's reader sees it
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["orccadd.log"]
    assert (meta["mission"], meta["orccadd_version"]) == ("PositionDemo", __version__), meta
    assert meta["config_sha256"] == sha(Path(meta["config"])) and meta["mission_deployment"] == ""
    assert daemon.ctl("fetch", "run1.csv", "-o", str(out)).returncode == 2  # exists: --force
    assert daemon.ctl("fetch", "run1.csv", "-o", str(out), "--force").returncode == 0


def test_what_is_not_one_of_its_logs_is_refused(daemon: Daemon, tmp_path: Path) -> None:
    for name, error in (
        ("../orccadd.sock", "is not a log of this daemon"),
        ("/etc/passwd", "is not a log of this daemon"),
        ("nothing.csv", "no log nothing.csv"),
    ):
        r = daemon.reply("fetch", name=name)
        assert not r["ok"] and error in r["error"], (name, r)
    r = daemon.reply("fetch", name="x.csv", length=1 << 20)
    assert not r["ok"] and "length (=1048576) in [1, 32768]" in r["error"], r
    p = daemon.ctl("fetch", "absent.csv", "-o", str(tmp_path))
    assert p.returncode == 2 and "no log 'absent.csv' on this daemon" in p.stderr, p.stderr
    assert daemon.status()["state"] == "idle"
