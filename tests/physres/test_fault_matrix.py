"""The resource rows of docs/fault-matrix.md, each injected under a moving Robot-Task on the wall
clock (or the device's cycle): the tick that reads the fault raises the type 3 exception and
safe-stops the arm within 2 ticks, the task ends in FAULT, and no tick, before or after, sent a
command outside the config's limits. (CANopen rows: tests/physres/test_canopen402.py.) The
EtherCAT rows run against the slave simulator (root: its network namespace)."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from orccadd.ecatsim.process import EcatSimProcess
from orccadd.physres import PhysicalResource
from orccadd.physres.sim_process import SimProcessArm
from orccadd.robot import load_robot_config, with_backend
from orccadd.session import Session
from orccadd.task.loop import resource_clock
from orccadd.types import Phase, Status
from tests.conftest import MOVE_TASK, ROOT, UR5E
from tests.safety import TickRecorder, assert_commands_within_limits, assert_safe_stop_in_time, status_shows

FAR = [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]
ECAT = ROOT / "configs/robots/ethercat-6axis-sim.toml"


def kill_plant(res: PhysicalResource, sim: Any = None) -> Callable[[], None]:
    def inject() -> None:
        assert isinstance(res, SimProcessArm)
        res.process.kill()
        res.process.wait()

    return inject


def stall_plant(res: PhysicalResource, sim: Any = None) -> Callable[[], None]:
    assert isinstance(res, SimProcessArm)
    return lambda: os.kill(res.process.pid, signal.SIGSTOP)


def device_fault(res: PhysicalResource, sim: Any = None) -> Callable[[], None]:
    return lambda: res.inject_fault("device", "over-current on axis 2")


def drive_overcurrent(res: PhysicalResource, sim: EcatSimProcess) -> Callable[[], None]:
    return lambda: sim.inject("overcurrent", device=2)


def slave_unplugged(res: PhysicalResource, sim: EcatSimProcess) -> Callable[[], None]:
    return lambda: sim.inject("unplug", device=4)


def simulator_killed(res: PhysicalResource, sim: EcatSimProcess) -> Callable[[], None]:
    return sim.kill


@dataclass(frozen=True)
class Row:
    backend: str
    settings: dict[str, object]
    inject: Callable[[PhysicalResource, Any], Callable[[], None]]
    shows: Status  # the flag the fault raises in the tick that reads it
    t3: str
    simulator: bool = field(default=False)  # the EtherCAT slave simulator behind it


ROWS = {
    "sim: device fault": Row("sim", {}, device_fault, Status.FAULT, "ResourceFault"),
    "sim_process: device fault": Row("sim_process", {}, device_fault, Status.FAULT, "ResourceFault"),
    "sim_process: plant process killed": Row("sim_process", {}, kill_plant, Status.COMM_LOST, "CommLost"),
    "sim_process (device-paced): stream stalls": Row(
        "sim_process", {"paced_by_plant": True}, stall_plant, Status.COMM_LOST, "CommLost"
    ),
    "ethercat402: drive over-current": Row(
        "ethercat402", {}, drive_overcurrent, Status.FAULT, "ResourceFault", simulator=True
    ),
    "ethercat402: slave unplugged": Row(
        "ethercat402", {}, slave_unplugged, Status.COMM_LOST, "CommLost", simulator=True
    ),
    "ethercat402: simulator killed": Row(
        "ethercat402", {}, simulator_killed, Status.COMM_LOST, "CommLost", simulator=True
    ),
}


@pytest.fixture(params=list(ROWS), ids=list(ROWS))
def row(request: pytest.FixtureRequest) -> Iterator[tuple[Row, Session, EcatSimProcess | None]]:
    r = ROWS[request.param]
    if r.simulator:
        if os.geteuid() != 0:
            pytest.skip("the EtherCAT simulator's link needs root")
        with EcatSimProcess(ECAT, "--priority", "70") as sim:
            s = Session.from_config(load_robot_config(ECAT))
            try:
                yield r, s, sim
            finally:
                s.close()
        return
    s = Session.from_config(with_backend(load_robot_config(UR5E), r.backend, **r.settings))
    try:
        yield r, s, None
    finally:
        if isinstance(s.resource, SimProcessArm) and s.resource.plant_alive():
            os.kill(s.resource.process.pid, signal.SIGCONT)
        s.close()


def test_the_fault_safe_stops_within_two_ticks_and_no_command_leaves_the_limits(
    row: tuple[Row, Session, EcatSimProcess | None],
) -> None:
    r, s, sim = row
    task = s.task(MOVE_TASK)
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    loop = TickRecorder(s.resource, resource_clock(s.resource), overrun_limit=10**6)
    loop.active = task
    task.activate()
    loop.run_for(0.3)  # moving
    r.inject(s.resource, sim)()
    loop.executor.run(max_ticks=200)  # ticks go on (a stalled stream releases the loop itself)
    assert task.phase is Phase.FAULT
    assert [n for n in s.event_names() if ".T3." in n] == [f"MoveJoints.T3.{r.t3}"]
    ticks = loop.ticks()
    assert_safe_stop_in_time(ticks, status_shows(ticks, r.shows))
    assert_commands_within_limits(ticks, s.config)
