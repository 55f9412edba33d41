"""The shipped UR missions that use the controller's own features, through orccadd/orccadctl on the
UR controller simulator, the world made as a user makes it (`python -m orccadd.simctl CONTROL
inject ...`, the commands each mission's comments give): the guarded move ends on the contact
with a table and goes back without one, the press reaches its force on the table by force mode,
freedrive follows a push and ends on the operator's input."""

from __future__ import annotations

import functools
import json
import shlex
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from orccadd.model import RobotModel
from orccadd.robot import load_robot_config
from orccadd.ursim.process import UrSimProcess
from tests.daemon.conftest import ROOT, Daemon, start_daemon_with
from tests.daemon.test_same_mission import local_config
from tests.daemon.test_ur_rtde import SIM_ARGS, UR

MISSIONS = ROOT / "configs/missions"
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
TABLE = ("wall", "point_m=[0,0,0.38]", "normal=[0,0,1]", "stiffness_n_m=5000")
HAND = ("push", "force_n=[8,0,0]", "duration_s=0.4")
TABLE_Z_M = 0.38

# ur_rtde blocks in C++ holding the interpreter: only a thread can time such a test out
pytestmark = pytest.mark.timeout(180, method="thread")


@pytest.fixture(scope="module")
def sim() -> Iterator[UrSimProcess]:
    with UrSimProcess(UR, *SIM_ARGS) as s:
        yield s


@pytest.fixture(scope="module")
def daemon(sim: UrSimProcess, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Daemon]:
    """One daemon for the module's runs (each mission starts from wherever the last left the arm)."""
    tmp = tmp_path_factory.mktemp("ur_missions")
    d = start_daemon_with(tmp, local_config(tmp, UR))
    try:
        yield d
    finally:
        d.stop()  # ur_rtde's clients go before the simulator does


@pytest.fixture(autouse=True)
def empty_world(sim: UrSimProcess, daemon: Daemon) -> Iterator[None]:
    """Each test finds no table, no mission running and nothing safe-stopped."""
    recover(daemon)
    simctl(sim, "inject", "wall_remove")
    yield
    simctl(sim, "inject", "wall_remove")


def recover(d: Daemon) -> None:
    """A failed test's run aborted; a safe stop since (the stream stalled on a loaded machine
    while the daemon held the arm: CommLost) reset once the arm is at rest."""
    if d.status()["state"] == "running":
        d.call("abort")
        d.wait(lambda s: s["state"] != "running", timeout_s=30)
    if not d.status()["faulted"]:
        return
    d.wait(lambda s: "stopped" in s.get("resource_status", []), timeout_s=30)
    deadline = time.monotonic() + 30
    while d.ctl("reset").returncode != 0:  # a protective stop unlocks 1 s after it (here)
        assert time.monotonic() < deadline, d.status()
        time.sleep(0.3)
    d.wait(lambda s: not s["faulted"] and not s.get("resource_status"), timeout_s=30)


def as_the_user_types_it(name: str, *argv: str) -> None:
    """`simctl ... inject ARGV` is written so in the mission's comments and docs/simulators.md."""
    line = f"python -m orccadd.simctl 127.0.0.1:30100 inject {shlex.join(argv)}"
    assert line in (MISSIONS / f"{name}.mission").read_text(), line
    assert line in (ROOT / "docs/simulators.md").read_text(), line


def simctl(sim: UrSimProcess, *argv: str) -> str:
    """`python -m orccadd.simctl CONTROL ARGV...` as a user runs it; its output."""
    cmd = [sys.executable, "-m", "orccadd.simctl", sim.control, *argv]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.returncode == 0, (cmd, r.stdout, r.stderr)
    return r.stdout


def sim_status(sim: UrSimProcess) -> dict[str, Any]:
    reply: dict[str, Any] = json.loads(simctl(sim, "status", "--json"))
    return reply


def run(d: Daemon, sim: UrSimProcess, name: str) -> list[dict[str, Any]]:
    """configs/missions/NAME.mission loaded and started, run to its end: success, nothing faulted;
    the trace's instants of this run."""
    return to_the_end(d, sim, start(d, name))


def start(d: Daemon, name: str) -> int:
    """configs/missions/NAME.mission loaded and started; the trace's last record before it."""
    before = d.call("events", last=1)["events"]
    r = d.ctl("load", str(MISSIONS / f"{name}.mission"))
    assert r.returncode == 0, r.stderr
    r = d.ctl("start")
    if r.returncode != 0 and "Hold.T3.CommLost" in r.stderr:  # stalled while idle: see `recover`
        recover(d)
        r = d.ctl("start")
    assert r.returncode == 0, r.stderr
    return int(before[-1]["seq"]) if before else -1


def to_the_end(d: Daemon, sim: UrSimProcess, after_seq: int) -> list[dict[str, Any]]:
    """The run's end (success, nothing faulted), and its instants (the trace after `after_seq`)."""
    s = d.wait(lambda s: s["state"] != "running" or s["faulted"], timeout_s=60)
    assert s["result"] == "success" and not s["faulted"], (s.get("fault"), sim.log_text()[-3000:])
    events = d.call("events", last=200)["events"]
    return [e for e in events if e["kind"] == "instant" and e["seq"] > after_seq]


def started(instants: list[dict[str, Any]]) -> list[str]:
    return [a.removeprefix("start ") for e in instants for a in e["actions"] if a.startswith("start ")]


def inputs(instants: list[dict[str, Any]]) -> list[str]:
    return [i for e in instants for i in e["inputs"]]


@functools.cache
def ur5e() -> RobotModel:
    return RobotModel.from_config(load_robot_config(UR))


def tcp_m(q_rad: list[float]) -> np.ndarray:
    """The tool's position in the base frame at `q_rad` (the controller's TCP: the flange)."""
    import pinocchio as pin

    m = ur5e().model
    data = m.createData()
    pin.framesForwardKinematics(m, data, np.asarray(q_rad, dtype=np.float64))
    return np.array(data.oMf[m.getFrameId("tool0")].translation)


def at_rest(st: dict[str, Any]) -> bool:
    return bool(max(abs(v) for v in st["dq_rad_s"]) < 1e-3)


def test_the_guarded_move_ends_on_its_contact_with_the_table(sim: UrSimProcess, daemon: Daemon) -> None:
    as_the_user_types_it("ur_guarded", *TABLE)
    simctl(sim, "inject", *TABLE)
    assert sim_status(sim)["wall"]["point_m"] == [0, 0, TABLE_Z_M]
    instants = run(daemon, sim, "ur_guarded")
    assert started(instants) == ["Home", "Approach"], instants
    assert "Approach.done" in inputs(instants) and "Approach.T2.NoContact" not in inputs(instants)
    st = sim.wait_for(at_rest, timeout_s=30)  # the Hold brakes within the limits, then holds
    assert abs(tcp_m(st["q_rad"])[2] - TABLE_Z_M) < 0.01, st  # held where it touched
    assert st["protective_stops"] == 0 and st["safety_mode"] == "NORMAL", st


def test_the_guarded_move_without_a_table_is_no_contact_and_goes_back(
    sim: UrSimProcess, daemon: Daemon
) -> None:
    assert sim_status(sim)["wall"] is None
    instants = run(daemon, sim, "ur_guarded")
    assert started(instants) == ["Home", "Approach", "Back"], instants
    assert "Approach.T2.NoContact" in inputs(instants) and "Approach.done" not in inputs(instants)
    assert np.abs(np.array(sim_status(sim)["q_rad"]) - HOME).max() < 0.01


def test_the_press_reaches_its_force_on_the_table_and_retreats(sim: UrSimProcess, daemon: Daemon) -> None:
    as_the_user_types_it("ur_press", *TABLE)
    simctl(sim, "inject", *TABLE)
    instants = run(daemon, sim, "ur_press")
    assert started(instants) == ["Approach", "Press", "Retreat"], instants
    assert [i for i in inputs(instants) if i.startswith("Press.")] == ["Press.done"], instants
    st = sim_status(sim)
    assert np.abs(np.array(st["q_rad"]) - HOME).max() < 0.01
    assert st["motion"] != "force_mode" and st["protective_stops"] == 0, st  # force mode ended


def test_freedrive_follows_a_push_and_ends_on_the_operators_input(sim: UrSimProcess, daemon: Daemon) -> None:
    seq = start(daemon, "ur_freedrive")
    daemon.wait(lambda s: s["active_task"] == "Guide", timeout_s=30)
    before = sim.wait_for(at_rest, timeout_s=30)
    as_the_user_types_it("ur_freedrive", *HAND)
    simctl(sim, "inject", *HAND)
    sim.wait_for(lambda st: tcp_m(st["q_rad"])[0] - tcp_m(before["q_rad"])[0] > 0.01, timeout_s=30)
    left = sim.wait_for(lambda st: at_rest(st) and not st["push_active"], timeout_s=30)  # let go: it stays
    s = daemon.status()
    assert s["state"] == "running" and s["active_task"] == "Guide", s  # until the operator says
    r = daemon.ctl("send", "Taught")
    assert r.returncode == 0, r.stderr
    instants = to_the_end(daemon, sim, seq)
    assert started(instants) == ["Guide", "Home"], instants
    assert "Taught" in inputs(instants)
    assert np.abs(np.array(sim_status(sim)["q_rad"]) - HOME).max() < 0.01
    assert np.linalg.norm(tcp_m(left["q_rad"]) - tcp_m(HOME)) > 0.01  # Home moved it back
