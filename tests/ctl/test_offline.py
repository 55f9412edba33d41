"""`orccadctl check | graph | export-promela`, run as a user would, in a separate process."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.automaton.conftest import KEEPSTABLE, NO_GUARD
from tests.conftest import ROOT


def ctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "orccadd.cli", *args], capture_output=True, text=True, timeout=120, cwd=ROOT
    )


def test_check_passes_keepstable() -> None:
    r = ctl("check", "--language-only", str(KEEPSTABLE))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "ok   conflicts" in r.stdout


def test_check_refuses_the_mutant_with_its_counterexample_as_json() -> None:
    r = ctl("check", "--json", "--language-only", str(NO_GUARD))
    assert r.returncode == 1
    out = json.loads(r.stdout)
    assert out["ok"] is False
    conflicts = next(c for c in out["checks"] if c["name"] == "conflicts")
    assert not conflicts["ok"]
    assert conflicts["counterexample"][0].startswith("instant 1:")


def test_check_reports_a_syntax_error_with_its_place(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mission"
    bad.write_text("mission M\nmain procedure P\n  do Go until\nend\n")
    r = ctl("check", str(bad))
    assert r.returncode == 1
    assert f"{bad}:4:1:" in r.stderr
    assert "Traceback" not in r.stderr
    j = ctl("check", "--json", str(bad))
    assert json.loads(j.stdout)["error"]["line"] == 4


def test_graph_draws_the_abstract_view(tmp_path: Path) -> None:
    out = tmp_path / "view.svg"
    r = ctl("graph", str(KEEPSTABLE), "--abstract", "KeepStableCam,KeepStableUS,Stop", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "4 states, 5 transitions" in r.stdout
    assert out.read_text().lstrip().startswith(("<?xml", "<svg"))
    dot = tmp_path / "full.dot"
    assert ctl("graph", str(KEEPSTABLE), "-o", str(dot)).returncode == 0
    assert dot.read_text().startswith('digraph "KeepStable"')


def test_graph_refuses_an_unknown_signal(tmp_path: Path) -> None:
    r = ctl("graph", str(KEEPSTABLE), "--abstract", "Nope", "-o", str(tmp_path / "x.svg"))
    assert r.returncode == 2
    assert "'Nope' is unknown" in r.stderr


def test_export_promela_writes_a_model(tmp_path: Path) -> None:
    out = tmp_path / "ks.pml"
    r = ctl("export-promela", str(KEEPSTABLE), "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "the structural model" in out.read_text()  # the default
    assert "active proctype b1()" in out.read_text()  # a process per parallel branch
    table = tmp_path / "table.pml"
    assert ctl("export-promela", str(KEEPSTABLE), "--model", "table", "-o", str(table)).returncode == 0
    assert "The table-replay model" in table.read_text()


def test_export_promela_refuses_an_unknown_property(tmp_path: Path) -> None:
    r = ctl("export-promela", str(KEEPSTABLE), "--property", "liveness", "-o", str(tmp_path / "x.pml"))
    assert r.returncode == 2
    assert "liveness: unknown (properties: safety, conflicts, properties)" in r.stderr
    assert not (tmp_path / "x.pml").exists()


def test_online_commands_do_not_load_the_compiler() -> None:
    code = (
        "import sys, orccadd.cli\n"
        "print(any(m.startswith(('lark', 'orccadd.automaton')) for m in sys.modules))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.stdout.strip() == "False", r.stderr


def test_check_refuses_what_load_refuses_and_language_only_does_not(tmp_path: Path) -> None:
    """One function for both: a mission with two tasks active at once on one resource (on
    disjoint joints) passes the language's checks but not the daemon's, with the shortest trace
    to the state as the counterexample."""
    two = tmp_path / "two.mission"
    two.write_text(
        TWO_AT_ONCE.replace("TASK", str(ROOT / "configs/tasks/move_joints.toml")), encoding="utf-8"
    )
    r = ctl("check", str(two))
    assert r.returncode == 1, r.stdout + r.stderr
    assert "FAIL one task per resource: Reach and Look active at once on arm" in r.stdout
    assert "instant 1:" in r.stdout
    assert ctl("check", "--language-only", str(two)).returncode == 0
    bare = ctl("check", str(NO_GUARD))
    assert bare.returncode == 1 and "FAIL task files: no task file for KeepStableUS (line 11)" in bare.stdout


TWO_AT_ONCE = """mission Two
resource arm
input Stop
task Reach on arm joints shoulder_pan_joint from "TASK"
  post
end
task Look on arm joints wrist_3_joint from "TASK"
  post
end
main procedure P
  handle
    PAR(Reach || Look)
  on fatal do safe end
end
safe procedure S
  await Stop
end
"""


def test_check_config_builds_every_task_on_the_robot(tmp_path: Path) -> None:
    # a misspelt module parameter passes the language's checks, and is caught on the robot
    text = (ROOT / "configs/missions/demo.mission").read_text()
    text = text.replace('"../tasks/', f'"{ROOT}/configs/tasks/').replace(
        "set traj.target_rad", "set traj.target_rads", 1
    )
    mission = tmp_path / "m.mission"
    mission.write_text(text)
    r = ctl("check", str(mission))  # a parameter's name does not depend on the robot: caught without
    assert r.returncode == 1 and "FAIL parameter names" in r.stdout, r.stdout
    assert "traj.target_rads is not a parameter of traj; did you mean target_rad?" in r.stdout, r.stdout
    r = ctl("check", str(mission), "--config", "sim-ur5e")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "FAIL robot ur5e" in r.stdout and "traj.target_rads is not a parameter" in r.stdout
    assert f"{mission}:11:" in r.stdout  # the `set` line
    ok = ctl("check", str(ROOT / "configs/missions/demo.mission"), "--config", "sim-ur5e", "--json")
    checks = {c["name"]: c for c in json.loads(ok.stdout)["checks"]}
    assert ok.returncode == 0 and checks["robot ur5e"]["ok"], ok.stdout
    bad = ctl("check", str(mission), "--config", "no-such-robot")
    assert bad.returncode == 2 and "no shipped robot config" in bad.stderr
    # a task copied without its goal (a required parameter): refused, naming it, not sent home
    home_goal = "  set traj.target_rads = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]\n"
    mission.write_text(text.replace(home_goal, ""))
    r = ctl("check", str(mission), "--config", "sim-ur5e")
    assert r.returncode == 1 and "task Home: traj.target_rad required" in r.stdout, r.stdout


def test_check_verifies_a_large_par_as_a_network() -> None:
    ten = ROOT / "benchmarks" / "missions" / "concurrent10.mission"
    r = ctl("check", "--language-only", "--json", str(ten))
    assert r.returncode == 0, r.stdout + r.stderr
    out = json.loads(r.stdout)
    assert out["ok"] and "a network" in out["network"] and "10 branches" in out["network"]
    # the daemon's check: the same network, with one task per resource on its products; refused
    # here only because its tasks have no task files
    daemon = ctl("check", "--json", str(ten))
    checks = {c["name"]: c for c in json.loads(daemon.stdout)["checks"]}
    assert daemon.returncode == 1 and "10 branches" in json.loads(daemon.stdout)["network"], daemon.stdout
    assert checks["one task per resource"]["ok"] and checks["safety"]["ok"], checks
    failed = [c["name"] for c in checks.values() if not c["ok"] and c["level"] == "error"]
    assert failed == ["task files"], failed


def test_graph_draws_a_network_component_by_component(tmp_path: Path) -> None:
    dot = tmp_path / "ten.dot"
    r = ctl("graph", str(ROOT / "benchmarks" / "missions" / "concurrent10.mission"), "-o", str(dot))
    assert r.returncode == 0, r.stderr
    text = dot.read_text()
    assert 'label="context"' in text and 'label="branch 10 of the par at line' in text
    assert "par paused" in text  # the context's edges say the par's code


def test_a_shipped_mission_is_checked_by_its_name() -> None:
    r = ctl("check", "demo")
    assert r.returncode == 0 and "mission PickDemo" in r.stdout, (r.stdout, r.stderr)
    r = ctl("check", "nosuch")
    assert r.returncode == 2 and "no shipped mission of that name (shipped: cell_handover_a" in r.stderr


def test_check_without_a_robot_says_which_checks_it_did_not_run_and_runs_them_on_the_services(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`check` ran only the language's checks without --config and printed ok for a misspelt
    parameter that `load` refuses: now it checks parameter names on a stand-in robot and warns
    that the robot's other checks did not run (--strict fails), and on a PC with the service's
    robot config it runs them on that robot."""
    from orccadd.cli import orccadctl_main as main
    from orccadd.config import shipped
    from tests.daemon.conftest import robot_config

    text = (ROOT / "configs/missions/demo.mission").read_text()
    text = text.replace('from "../tasks/', f'from "{ROOT}/configs/tasks/')
    typo = tmp_path / "typo.mission"
    typo.write_text(text.replace("set lost.threshold_rad", "set lost.treshold_rad"))
    monkeypatch.setattr(shipped, "SERVICE_CONFIG", tmp_path / "absent.toml")
    assert main(["check", str(typo)]) == 1
    out = capsys.readouterr().out
    assert "warn robot: not checked: no --config and no service config here" in out
    assert "FAIL parameter names: " in out and "lost.treshold_rad is not a parameter of lost" in out
    assert f"{typo}:" in out  # the `set` line's place
    assert main(["check", str(ROOT / "configs/missions/demo.mission")]) == 0  # names known: a warning
    assert main(["check", "--strict", str(ROOT / "configs/missions/demo.mission")]) == 1
    capsys.readouterr()
    task = tmp_path / "typo_task.toml"  # a misspelt name in a task file: the file and key named
    original = (ROOT / "configs/tasks/move_joints.toml").read_text()
    task.write_text(original.replace("tolerance_rad", "tolerence_rad"))
    typo.write_text(text.replace(f'"{ROOT}/configs/tasks/move_joints.toml"', f'"{task}"'))
    assert main(["check", str(typo)]) == 1
    out = capsys.readouterr().out
    assert f"{task}: modules." in out and "tolerence_rad is not a parameter" in out, out
    monkeypatch.setattr(shipped, "SERVICE_CONFIG", robot_config(tmp_path))  # this PC's robot
    assert main(["check", str(typo)]) == 1
    assert "FAIL robot ur5e:" in capsys.readouterr().out
    assert main(["check", str(typo), "--config", "sim-ur5e"]) == 1


def test_check_on_a_cell_refuses_a_task_on_a_resource_it_lacks_as_load_does() -> None:
    grasp = str(ROOT / "configs/missions/grasp.mission")
    r = ctl("check", grasp, "--config", "dual-arm-sim")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "task Open runs on `gripper`, but this robot's resources are `left`, `right`" in r.stdout
    assert ctl("check", grasp, "--config", "ur5e-gripper-sim").returncode == 0
