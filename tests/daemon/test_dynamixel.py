"""orccadd on a simulated DYNAMIXEL chain (configs/robots/dxl-6axis-sim.toml), everything in its
own process: the servo simulator (`python -m orccadd.dxlsim` on a pseudo-terminal), orccadd
(real-time process + command daemon) and orccadctl. The resource-level checks (every startup
check, the fault bits, the stop ramp against the limits) are tests/physres/test_dynamixel.py's;
here: what the daemon makes of them."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import cast

import pytest

from orccadd.fault import cause_words
from tests.daemon.conftest import ROOT, Daemon, mission_dirs, moving, start_daemon_with
from tests.physres.test_dynamixel import SIM, DxlRig, dxl_rig

DEMO = str(ROOT / "configs/missions/demo_position.mission")
SIM_PRIORITY = 70  # as the other simulators in the daemon tests (canopen_rig, UrSimProcess)
HELD_RAD = 0.005  # how far a held joint may move in 0.5 s (3 position units of 1.5 mrad)
pytestmark = pytest.mark.timeout(180, method="thread")


@contextmanager
def dxl_daemon_rig(tmp: Path, *edits: tuple[str, str], base: Path = SIM) -> Iterator[DxlRig]:
    """`dxl_rig` (the simulator on a pseudo-terminal under `tmp`) with a config orccadd runs from
    `tmp`: the hold task's path made absolute, the shipped and the tests' missions allowed."""
    daemon = (
        ('hold_task = "../tasks/', f'hold_task = "{ROOT}/configs/tasks/'),
        (
            "[daemon]\n",
            f'[daemon]\nmission_dirs = [{mission_dirs(tmp)}]\ntask_dirs = ["{ROOT}/configs/tasks"]\n',
        ),
    )
    # The servos are hardware: their answers must not wait for the controller's load. At
    # normal priority the simulator (one thread) was starved beside orccadd's SCHED_FIFO loop
    # and its mission compiler on this 2-core VM: 5 sync reads in a row (25 ms) unanswered,
    # CommLost. So it runs at SCHED_FIFO, as the other simulators of the daemon tests.
    with dxl_rig(tmp, *daemon, *edits, sim_args=("--priority", str(SIM_PRIORITY)), base=base) as rig:
        yield rig


@pytest.fixture
def rig_daemon(tmp_path: Path) -> Iterator[tuple[DxlRig, Daemon]]:
    with dxl_daemon_rig(tmp_path) as rig:
        d = start_daemon_with(tmp_path, rig.config)
        try:
            yield rig, d
        finally:
            d.stop()


def _resource(s: dict[str, object]) -> list[str]:
    return cast(list[str], s.get("resource_status", []))


def _safe_stopped(s: dict[str, object]) -> bool:
    """The type 3 recorded and the arm at rest after its safe stop."""
    return bool(s["faulted"]) and "stopped" in _resource(s)


def _t3_inputs(d: Daemon) -> list[str]:
    ev = d.call("events", last=40)
    inputs = [i for e in ev["events"] if e["kind"] == "instant" for i in e["inputs"]]  # type: ignore[index]
    return [i for i in inputs if ".T3." in i]


def _held(rig: DxlRig, joints: list[int], seconds: float = 0.5) -> float:
    """How far the simulated arm's `joints` moved over `seconds` (the arm, not a register)."""
    q0 = rig.sim.status()["q_rad"]
    time.sleep(seconds)
    q1 = rig.sim.status()["q_rad"]
    return float(max(abs(q1[j] - q0[j]) for j in joints))


def test_a_wrong_servo_model_stops_orccadd_at_startup_naming_the_servo(tmp_path: Path) -> None:
    with dxl_daemon_rig(tmp_path) as rig:
        wrong = rig.variant(('id = 4\nmodel = "XM430-W350"', 'id = 4\nmodel = "XM540-W270"'))
        sock = tmp_path / "run/orccadd.sock"
        cmd = [sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(wrong), "--socket", str(sock)]
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        servos = rig.sim.status()["servos"]
    assert out.returncode == 2, out.stderr
    assert (
        "servo 4 (forearm_roll, XM540-W270): the servo with ID 4 is a XM430-W350 (1020), "
        "the config says XM540-W270 (1120)"
    ) in out.stderr, out.stderr
    assert not sock.exists()
    assert not any(s["torque_enable"] for s in servos)  # nothing was switched on


def test_an_overload_mid_motion_safe_stops_holds_and_a_reset_reboots_the_servo(
    rig_daemon: tuple[DxlRig, Daemon],
) -> None:
    rig, d = rig_daemon
    r = d.ctl("load", DEMO)
    assert r.returncode == 0, r.stderr
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach" and moving(s))
    rig.sim.inject("overload", device=1)  # the waist: its torque goes off, it coasts on its friction
    s = d.wait(_safe_stopped, timeout_s=30)
    assert _t3_inputs(d) == ["Reach.T3.ResourceFault"]
    assert "servo 1 (waist, XM540-W270): hardware error: overload (bit 5)" in str(s["fault"]), s["fault"]
    assert s["state"] == "running"  # the safe procedure awaits the operator's Stop
    servos = rig.sim.status()["servos"]
    assert (servos[0]["hardware_error_status"], servos[0]["torque_enable"]) == (0x20, 0)
    assert all(sv["torque_enable"] == 1 for sv in servos[1:])  # category 2: the others hold the arm
    moved = _held(rig, list(range(6)))
    assert moved < HELD_RAD, f"the stopped arm moved {moved:.4f} rad in 0.5 s"
    d.call("stop")
    d.wait(lambda s: s["state"] == "ready")
    r = d.ctl("reset")
    assert r.returncode == 0, r.stdout + r.stderr
    d.wait(lambda s: not s["faulted"])
    servo1 = rig.sim.status()["servos"][0]
    assert (servo1["hardware_error_status"], servo1["torque_enable"]) == (0, 1)  # rebooted, re-enabled
    r = d.ctl("start")
    assert r.returncode == 0, r.stderr
    s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success" and not s["faulted"], s


def test_an_unplugged_servo_is_comm_lost_naming_it_and_the_arm_safe_stops(
    rig_daemon: tuple[DxlRig, Daemon],
) -> None:
    rig, d = rig_daemon
    d.call("load", path=DEMO)
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach" and moving(s))
    rig.sim.inject("unplug", device=5)  # wrist_angle: no answer, no torque
    s = d.wait(_safe_stopped, timeout_s=30)
    assert "comm_lost" in _resource(s), _resource(s)
    assert _t3_inputs(d) == ["Reach.T3.CommLost"]
    assert "servo 5 (wrist_angle, XM430-W350) does not answer" in str(s["fault"]), s["fault"]
    assert s["state"] == "running"  # the safe procedure awaits the operator's Stop
    others = [0, 1, 2, 3, 5]  # still read, stopped and held; the unplugged wrist hangs on its own
    assert all(rig.sim.status()["servos"][j]["torque_enable"] == 1 for j in others)
    moved = _held(rig, others)
    assert moved < HELD_RAD, f"the stopped arm moved {moved:.4f} rad in 0.5 s"
    d.call("stop")
    d.wait(lambda s: s["state"] == "ready")


def test_the_port_vanishing_mid_motion_is_comm_lost_the_loop_ticks_on_and_reset_reopens_it_once_back(
    rig_daemon: tuple[DxlRig, Daemon],
) -> None:
    """The servo simulator killed mid-motion, as a USB adapter unplugged (issue 40, high item 3:
    the control thread spun at SCHED_FIFO 80 in the port's drop of a late reply and ticked no
    more, status said not faulted, `reset` timed out, then answered "already under way" for
    ever, SIGTERM did nothing). Now: CommLost naming the port, the arm's safe stop, the control
    thread ticking on; `reset` refused naming the port while it is gone; the simulator restarted
    on the same link: `reset` opens it again, the arm holds, and the mission runs again."""
    rig, d = rig_daemon
    d.call("load", path=DEMO)
    d.call("start")
    d.wait(lambda s: s["active_task"] == "Reach" and moving(s))
    rig.sim.kill()
    s = d.wait(_safe_stopped, timeout_s=30)
    assert "comm_lost" in _resource(s), _resource(s)
    assert _t3_inputs(d) == ["Reach.T3.CommLost"]
    assert f"arm: the port {rig.port} is gone (" in cause_words(s["fault"]), s["fault"]
    ticks = int(s["ticks"])
    d.wait(lambda s: int(s["ticks"]) > ticks + 100, timeout_s=30)  # the control thread ticks on
    d.call("stop")
    d.wait(lambda s: s["state"] == "ready")
    r = d.ctl("reset")
    assert r.returncode != 0, r.stdout + r.stderr
    assert f"the port {rig.port} is still gone" in r.stdout + r.stderr, r.stdout + r.stderr
    assert d.status()["faulted"]
    r = d.ctl("reset")  # refused again in the same words: no reset left "under way"
    assert r.returncode != 0 and f"the port {rig.port} is still gone" in r.stdout + r.stderr, r.stderr
    q = [j["q_rad"] for j in cast(list[dict[str, float]], d.status()["joints"])]
    rig.restart("--initial-q-rad", ",".join(f"{x:.6f}" for x in q))  # at the same priority
    r = d.ctl("reset")
    assert r.returncode == 0, r.stdout + r.stderr
    d.wait(lambda s: not s["faulted"] and "comm_lost" not in _resource(s))
    assert all(sv["torque_enable"] == 1 for sv in rig.sim.status()["servos"])
    moved = _held(rig, list(range(6)))
    assert moved < HELD_RAD, f"the arm moved {moved:.4f} rad in 0.5 s after the reset"
    r = d.ctl("start")
    assert r.returncode == 0, r.stderr
    s = d.wait(lambda s: s["state"] != "running", timeout_s=60)
    assert s["result"] == "success" and not s["faulted"], s


def test_sigterm_with_the_port_gone_stops_the_daemon(tmp_path: Path) -> None:
    """SIGTERM after the port vanished: the daemon exits by itself (it needed SIGKILL), the stop
    counted as done (the servos hold their last goals), the servos left as they are."""
    with dxl_daemon_rig(tmp_path) as rig:
        d = start_daemon_with(tmp_path, rig.config)
        try:
            rig.sim.kill()
            s = d.wait(_safe_stopped, timeout_s=30)
            assert f"arm: the port {rig.port} is gone (" in cause_words(s["fault"]), s["fault"]
        finally:
            code = d.stop()  # SIGTERM, SIGKILL after 20 s
    log = d.log_text()
    assert code == 0, f"exit code {code}\n{log[-4000:]}"
    assert f"the port {rig.port} is gone: the servos are left as they are" in log, log[-4000:]
    assert "at rest, hardware released" in log, log[-4000:]
