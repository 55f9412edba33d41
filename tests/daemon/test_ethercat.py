"""orccadd on an EtherCAT arm, everything in its own process: the slave simulator on its veth link
(six CiA 402 drives), orccadd (real-time process + command daemon, SOEM on the master's end of
the link) and orccadctl. Startup, a mission in CSP and CST, a drive fault (type 3, quick stop,
reset, a new run), a slave unplugged (the line lost, reset re-walking its states), the
simulator killed (the daemon carries on, the arm stopped)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.ecatsim.process import EcatSimProcess
from tests.daemon.conftest import ROOT, Daemon, mission_dirs, start_daemon_with

pytest.importorskip("pysoem")
pytestmark = [
    pytest.mark.skipif(os.geteuid() != 0, reason="the simulator's link needs root"),
    pytest.mark.timeout(300, method="thread"),
]

CONFIG = ROOT / "configs/robots/ethercat-6axis-sim.toml"
MIXED = str(Path(__file__).resolve().parent / "missions/canopen.mission")  # CSP, then CST
DEMO = str(ROOT / "configs/missions/demo_position.mission")


def local_config(tmp: Path) -> Path:
    """The shipped simulated line with absolute paths and the tests' mission directories."""
    text = CONFIG.read_text().replace('"../', f'"{ROOT / "configs"}/')
    text = text.replace("mission_dirs = [", f"mission_dirs = [{mission_dirs(tmp)}, ")
    text = text.replace("\n[daemon]\n", f'\n[daemon]\ntask_dirs = ["{ROOT / "configs/tasks"}"]\n', 1)
    path = tmp / CONFIG.name
    path.write_text(text)
    return path


def moving(d: Daemon) -> None:
    """demo_position.mission started, its second motion under way."""
    d.call("load", path=DEMO)
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach")


def stopped_then_reset(d: Daemon) -> None:
    """The operator's Stop for the safe procedure, then `orccadctl reset`, the fault gone."""
    d.call("stop")
    d.wait(lambda s: s["state"] == "ready")
    r = d.ctl("reset")
    assert r.returncode == 0, r.stdout + r.stderr
    d.wait(lambda s: not s["faulted"], timeout_s=30)


def runs_to_success(d: Daemon) -> None:
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], s


@pytest.fixture
def line(tmp_path: Path) -> Iterator[tuple[EcatSimProcess, Daemon]]:
    with EcatSimProcess(CONFIG, "--priority", "70") as sim:
        d = start_daemon_with(tmp_path, local_config(tmp_path))
        try:
            yield sim, d
        finally:
            d.stop()  # before the simulator goes


def test_startup_enables_every_drive_in_op(line: tuple[EcatSimProcess, Daemon]) -> None:
    sim, d = line
    st = sim.status()
    assert st["al_states"] == ["OP"] * 6 and st["al_status_codes"] == [0] * 6
    assert [dev["state"] for dev in st["devices"]] == ["OPERATION_ENABLED"] * 6
    desc = d.call("describe")
    arm = desc["resources"][0] if "resources" in desc else desc
    assert arm["backend"] == "ethercat402", arm


def test_a_mission_with_csp_and_cst_motions_completes(line: tuple[EcatSimProcess, Daemon]) -> None:
    sim, d = line
    r = d.ctl("load", MIXED)
    assert r.returncode == 0, r.stderr
    d.call("start")
    s = d.wait(lambda s: s["state"] != "running", timeout_s=90)
    assert s["result"] == "success" and not s["faulted"], s
    q = [j["q_rad"] for j in s["joints"]]
    assert q == pytest.approx([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], abs=0.01)
    assert sim.status()["q_rad"] == pytest.approx(q, abs=0.01)  # the drives agree


def test_a_drive_fault_quick_stops_then_reset_and_a_new_run(line: tuple[EcatSimProcess, Daemon]) -> None:
    sim, d = line
    moving(d)
    sim.inject("overcurrent", device=2)
    s = d.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []), timeout_s=30)
    assert "slave 2 (shoulder_lift_joint)" in str(s["fault"]) and "0x2310" in str(s["fault"]), s["fault"]
    states = [dev["state"] for dev in sim.status()["devices"]]
    assert states[1] == "FAULT" and all(st in ("SWITCH_ON_DISABLED", "FAULT") for st in states), states
    stopped_then_reset(d)
    assert [dev["state"] for dev in sim.status()["devices"]] == ["OPERATION_ENABLED"] * 6
    runs_to_success(d)


def test_an_unplugged_slave_is_a_lost_line_and_reset_walks_it_back(
    line: tuple[EcatSimProcess, Daemon],
) -> None:
    sim, d = line
    moving(d)
    sim.inject("unplug", device=4)
    s = d.wait(lambda s: s["faulted"] and "stopped" in s.get("resource_status", []), timeout_s=30)
    assert "slave 4 (wrist_1_joint)" in str(s["fault"]), s["fault"]
    # the slaves beyond the cut lose their outputs: their SM watchdog (100 ms), their drives off
    st = sim.wait_for(lambda st: st["al_status_codes"][3:] == [0x001B] * 3, timeout_s=5.0)
    assert all(dev["state"] != "OPERATION_ENABLED" for dev in st["devices"][3:]), st["devices"]
    sim.inject("replug")
    stopped_then_reset(d)
    st = sim.status()
    assert st["al_states"] == ["OP"] * 6
    assert [dev["state"] for dev in st["devices"]] == ["OPERATION_ENABLED"] * 6
    runs_to_success(d)


def test_the_simulator_killed_stops_the_arm_and_the_daemon_carries_on(
    line: tuple[EcatSimProcess, Daemon],
) -> None:
    sim, d = line
    moving(d)
    sim.kill()
    s = d.wait(lambda s: s["faulted"], timeout_s=30)
    assert "EtherCAT line on ecm0" in str(s["fault"]), s["fault"]
    s = d.wait(lambda s: "stopped" in s.get("resource_status", []), timeout_s=30)
    assert d.status()["state"] in ("running", "ready")  # still answering
