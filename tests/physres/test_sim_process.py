"""The plant in its own process: the watchdogs on both sides of the link."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from orccadd.kinematics import ToolKinematics
from orccadd.physres.description import ClockSource
from orccadd.physres.sim_process import SimProcessArm
from orccadd.robot import load_robot_config, with_backend
from orccadd.runtime import WallClock
from orccadd.runtime.clock import DevicePacedClock
from orccadd.session import Session
from orccadd.simproc import control_request
from orccadd.task.loop import resource_clock
from orccadd.types import Phase, Status
from tests.conftest import MOVE_TASK, ROOT, UR5E


@pytest.fixture
def session() -> Iterator[Session]:
    s = Session.from_config(with_backend(load_robot_config(UR5E), "sim_process"))
    yield s
    s.close()
    assert not s.resource.plant_alive()  # type: ignore[attr-defined]


def test_motion_through_the_process_link(session: Session) -> None:
    task = session.task(MOVE_TASK)
    loop = session.loop(WallClock(), overrun_limit=10**6)
    phase = loop.run_task(task, timeout_s=6.0)
    assert phase is Phase.DONE, (task.fault_reason, session.resource.fault_message)
    assert session.event_names() == ["MoveJoints.pre", "MoveJoints.done"]


def test_the_plants_world_is_set_through_its_control_channel_and_felt_by_the_resource(
    session: Session,
) -> None:
    """The plant's control channel (its address in the resource's details) places a plane the
    tool is in: the resource reads the plant's sensor (`arm.wrench`) through the shared memory."""
    res = session.resource
    assert isinstance(res, SimProcessArm)
    address = res.diagnostics().details["plant_control"]
    assert isinstance(address, str) and address.startswith("127.0.0.1:")
    z = ToolKinematics(res.model).pose(res.state.q_rad).translation[2]
    plane = {"point_m": [0.0, 0.0, z + 0.005], "normal": [0.0, 0.0, 1.0], "stiffness_n_m": 5000.0}
    assert control_request(address, {"inject": "plane", **plane}) == {"ok": True}
    task = session.task(ROOT / "configs/tasks/hold.toml")
    loop = session.loop(WallClock(), overrun_limit=10**6)
    loop.active = task
    task.activate()
    loop.run_for(0.3)
    fz = res.signals["wrench"][2]
    assert 0.5 < fz < 5000.0 * 0.005 + 1.0, res.signals["wrench"]  # pushed up, the hold's PD yielding
    assert control_request(address, {"inject": "clear_world"}) == {"ok": True}
    loop.run_for(0.05)
    assert res.signals["wrench"] == pytest.approx([0.0] * 6)


def test_plant_killed_is_comm_lost_type_3(session: Session) -> None:
    task = session.task(MOVE_TASK)
    loop = session.loop(WallClock(), overrun_limit=10**6)
    loop.active = task
    task.activate()
    loop.run_for(0.1)
    res = session.resource
    assert isinstance(res, SimProcessArm)
    res.process.kill()
    res.process.wait()
    loop.run_for(0.25)  # 125 periods: beyond the 50-period (100 ms) heartbeat timeout
    assert task.phase is Phase.FAULT
    names = session.event_names()  # a frozen state may first look like tracking drift (T1)
    assert [n for n in names if ".T3." in n] == ["MoveJoints.T3.CommLost"], names
    assert "stopped answering" in res.fault_message


def test_silent_controller_makes_the_plant_stop_itself(session: Session) -> None:
    task = session.task(MOVE_TASK)
    loop = session.loop(WallClock(), overrun_limit=10**6)
    loop.active = task
    task.activate()
    loop.run_for(0.1)
    time.sleep(0.3)  # the controller stalls for 150 periods; the plant's watchdog is 50 (100 ms)
    loop.run_for(0.02)
    assert task.phase is Phase.FAULT
    names = session.event_names()
    assert [n for n in names if ".T3." in n] == ["MoveJoints.T3.ResourceFault"], names
    assert "command watchdog" in session.resource.fault_message
    end = time.monotonic() + 1.5  # the plant's own stop, from speed, within the 1.5 s it was given
    while not session.resource.read(time.monotonic()).status & Status.STOPPED and time.monotonic() < end:
        time.sleep(0.02)
    assert session.resource.state.status & Status.STOPPED


def test_controller_process_killed_plant_stops_and_exits(tmp_path) -> None:  # type: ignore[no-untyped-def]
    script = tmp_path / "controller.py"
    script.write_text(f"""
import os, sys
sys.path.insert(0, {str(ROOT)!r})
from orccadd.robot import load_robot_config, with_backend
from orccadd.runtime import WallClock
from orccadd.runtime.clock import DevicePacedClock
from orccadd.session import Session
from orccadd.simproc import control_request
from orccadd.task.loop import resource_clock
s = Session.from_config(with_backend(load_robot_config({str(UR5E)!r}), "sim_process"))
task = s.task({str(MOVE_TASK)!r})
loop = s.loop(WallClock(), overrun_limit=10**6)
loop.active = task
task.activate()
loop.run_for(0.3)
print(s.resource.diagnostics().helper_pid, flush=True)
os._exit(9)  # the controller dies mid-motion
""")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    plant_pid = int(out.stdout.strip().splitlines()[-1])
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            os.kill(plant_pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        os.kill(plant_pid, 9)
        pytest.fail("the plant kept running after its controller died")


@pytest.fixture
def paced() -> Iterator[Session]:
    """The plant's own cycle paces the loop, as a UR controller's RTDE stream does."""
    s = Session.from_config(with_backend(load_robot_config(UR5E), "sim_process", paced_by_plant=True))
    yield s
    s.close()


def test_a_device_paced_loop_ticks_on_the_plants_cycle(paced: Session) -> None:
    res = paced.resource
    assert res.description.clock is ClockSource.DEVICE
    clock = resource_clock(res)
    assert isinstance(clock, DevicePacedClock)
    task = paced.task(MOVE_TASK)
    loop = paced.loop(clock, overrun_limit=10**6)
    phase = loop.run_task(task, timeout_s=6.0)
    assert phase is Phase.DONE, (task.fault_reason, paced.resource.fault_message)
    stats = loop.stats
    period_us = res.config.control_period_s * 1e6
    # the releases follow the plant's steps, not a deadline of ours (an order of magnitude)
    assert period_us / 3 < stats.release_period.median_us < 3 * period_us
    assert stats.latency.median_us < period_us  # the tick starts when the cycle arrives


def test_a_stalled_device_still_releases_the_loop_which_reports_comm_lost(paced: Session) -> None:
    res = paced.resource
    assert isinstance(res, SimProcessArm)
    task = paced.task(MOVE_TASK)
    loop = paced.loop(resource_clock(res), overrun_limit=10**6)
    loop.active = task
    task.activate()
    loop.run_for(0.1)
    ticks = loop.stats.ticks
    os.kill(res.process.pid, signal.SIGSTOP)  # the stream stalls: no cycle arrives
    try:
        t0 = time.monotonic()
        loop.executor.run(max_ticks=60)  # released by the clock's stall timeout, not by the plant
        assert time.monotonic() - t0 < 60 * 3 * res.config.control_period_s * 10
        assert loop.stats.ticks == ticks + 60  # 60 x 3 periods: beyond the 50-period heartbeat
        assert task.phase is Phase.FAULT
        assert [n for n in paced.event_names() if ".T3." in n] == ["MoveJoints.T3.CommLost"]
    finally:
        os.kill(res.process.pid, signal.SIGCONT)


def test_the_watchdogs_default_to_100_ms_at_any_period_and_keep_a_count_set() -> None:
    """A watchdog counted in periods tolerates less at a shorter period (a cell runs an arm at
    1 kHz from its 500 Hz config): by default both watchdogs count 100 ms, at least 20 periods."""
    s = with_backend(load_robot_config(UR5E), "sim_process").backend_settings
    assert (s.watchdog_periods, s.heartbeat_timeout_periods) == (0, 0)
    assert [s.periods(0, p) for p in (0.001, 0.002, 0.008)] == [100, 50, 20]
    assert s.periods(7, 0.001) == 7
