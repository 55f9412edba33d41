"""`orccadctl deploy`: a mission and its task files from a workstation's directory to a daemon,
checked as `load` checks, stored by content; loaded and run by name or hash; a refusal stores
nothing; what the request carries is checked."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from orccadd.daemon.deploy import content_hash
from tests.daemon.conftest import ROOT, Daemon


def workstation(tmp: Path, name: str, mission: str = "demo_position") -> Path:
    """A workstation's copy of a shipped mission and its tasks, the layout configs/ has."""
    ws = tmp / "ws"
    (ws / "missions").mkdir(parents=True, exist_ok=True)
    if not (ws / "tasks").exists():
        shutil.copytree(ROOT / "configs/tasks", ws / "tasks")
    path = ws / "missions" / f"{name}.mission"
    path.write_text((ROOT / "configs/missions" / f"{mission}.mission").read_text())
    return path


def deployments() -> set[str]:
    return {p.name for p in (Path(os.environ["STATE_DIRECTORY"]) / "deployments").glob("*")}


def test_a_deployed_mission_is_checked_stored_once_loaded_by_name_and_run(
    daemon: Daemon, tmp_path: Path
) -> None:
    mission = workstation(tmp_path, "ws_demo")
    p = daemon.ctl("deploy", str(mission), "--json")
    assert p.returncode == 0, p.stdout + p.stderr
    first = json.loads(p.stdout)["result"]
    assert first["stored"] and first["name"] == "ws_demo" and first["by"] == "user root"
    files = {
        "../tasks/move_joints_csp.toml": (mission.parent.parent / "tasks/move_joints_csp.toml").read_text()
    }
    assert first["deployed"] == content_hash("ws_demo", mission.read_text(), files)
    again = daemon.ctl("deploy", str(mission))
    assert again.returncode == 0 and again.stdout.startswith(
        f"already deployed: ws_demo {first['deployed'][:12]}"
    )
    stored = Path(os.environ["STATE_DIRECTORY"]) / "deployments" / first["deployed"]
    record = json.loads((stored / "deployment.json").read_text())
    assert record["files"]["ws_demo.mission"] and sorted(p.name for p in (stored / "tasks").iterdir())
    assert daemon.ctl("load", "ws_demo").returncode == 0
    assert daemon.call("describe")["mission"]["deployment"] == first["deployed"]  # type: ignore[index]
    assert daemon.ctl("start").returncode == 0
    s = daemon.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success", s
    assert daemon.ctl("load", first["deployed"][:10]).returncode == 0  # by its hash's first digits


def test_a_mission_that_fails_a_check_is_refused_and_nothing_is_stored(
    daemon: Daemon, tmp_path: Path
) -> None:
    mission = workstation(tmp_path, "ws_bad")
    mission.write_text(
        mission.read_text().replace("set traj.speed_scale = 0.4", "set traj.speed_scale = 4.0", 1)
    )
    before = deployments()
    p = daemon.ctl("deploy", str(mission))
    assert p.returncode == 1 and "traj.speed_scale (=4.0) must be in [0.01, 1]" in p.stderr, p.stderr
    assert deployments() == before  # the staging removed too
    assert daemon.ctl("load", "ws_bad").returncode != 0


def test_what_the_request_carries_is_checked_before_anything_is_written(
    daemon: Daemon, tmp_path: Path
) -> None:
    text = (ROOT / "configs/missions/demo_position.mission").read_text()
    task = (ROOT / "configs/tasks/move_joints_csp.toml").read_text()
    before = deployments()
    cases = [
        ({"name": "../escape", "mission": text}, "name '../escape' must be 1-64 letters"),
        (
            {"name": "x", "mission": text},
            "the mission names ../tasks/move_joints_csp.toml, which the deployment does not carry",
        ),
        (
            {
                "name": "x",
                "mission": text,
                "task_files": ["../tasks/move_joints_csp.toml", "/etc/passwd"],
                "task_texts": [task, "root"],
            },
            "/etc/passwd: not named by the mission",
        ),
        (
            {"name": "x", "mission": text, "task_files": ["a"], "task_texts": []},
            "1 task file names for 0 texts",
        ),
    ]
    for args, error in cases:
        r = daemon.reply("deploy", **args)
        assert not r["ok"] and error in str(r["error"]), (args["name"], r)
    assert deployments() == before
    forged = daemon.reply(
        "deploy",
        name="forged",
        mission=text,
        task_files=["../tasks/move_joints_csp.toml"],
        task_texts=[task],
        by="mallory",
    )
    assert forged["ok"] and forged["result"]["by"] == "user root"  # the command daemon says who
    assert daemon.status()["state"] in ("idle", "ready")
