"""The resource rows of docs/fault-matrix.md, each injected under a moving Robot-Task on the wall
clock (or the device's cycle): the tick that reads the fault raises the type 3 exception and
safe-stops the arm within 2 ticks, the task ends in FAULT, and no tick, before or after, sent a
command outside the config's limits. (CANopen rows: tests/physres/test_canopen402.py.)"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from orccadd.physres import PhysicalResource
from orccadd.physres.sim_process import SimProcessArm
from orccadd.robot import load_robot_config, with_backend
from orccadd.session import Session
from orccadd.task.loop import resource_clock
from orccadd.types import Phase, Status
from tests.conftest import MOVE_TASK, UR5E
from tests.safety import TickRecorder, assert_commands_within_limits, assert_safe_stop_in_time, status_shows

FAR = [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]


def kill_plant(res: PhysicalResource) -> Callable[[], None]:
    def inject() -> None:
        assert isinstance(res, SimProcessArm)
        res.process.kill()
        res.process.wait()

    return inject


def stall_plant(res: PhysicalResource) -> Callable[[], None]:
    assert isinstance(res, SimProcessArm)
    return lambda: os.kill(res.process.pid, signal.SIGSTOP)


def device_fault(res: PhysicalResource) -> Callable[[], None]:
    return lambda: res.inject_fault("device", "over-current on axis 2")


@dataclass(frozen=True)
class Row:
    backend: str
    settings: dict[str, object]
    inject: Callable[[PhysicalResource], Callable[[], None]]
    shows: Status  # the flag the fault raises in the tick that reads it
    t3: str


ROWS = {
    "sim: device fault": Row("sim", {}, device_fault, Status.FAULT, "ResourceFault"),
    "sim_process: device fault": Row("sim_process", {}, device_fault, Status.FAULT, "ResourceFault"),
    "sim_process: plant process killed": Row("sim_process", {}, kill_plant, Status.COMM_LOST, "CommLost"),
    "sim_process (device-paced): stream stalls": Row(
        "sim_process", {"paced_by_plant": True}, stall_plant, Status.COMM_LOST, "CommLost"
    ),
}


@pytest.fixture(params=list(ROWS), ids=list(ROWS))
def row(request: pytest.FixtureRequest) -> Iterator[tuple[Row, Session]]:
    r = ROWS[request.param]
    s = Session.from_config(with_backend(load_robot_config(UR5E), r.backend, **r.settings))
    try:
        yield r, s
    finally:
        if isinstance(s.resource, SimProcessArm) and s.resource.plant_alive():
            os.kill(s.resource.process.pid, signal.SIGCONT)
        s.close()


def test_the_fault_safe_stops_within_two_ticks_and_no_command_leaves_the_limits(
    row: tuple[Row, Session],
) -> None:
    r, s = row
    task = s.task(MOVE_TASK)
    next(m for m in task.modules if m.name == "traj").configure({"target_rad": FAR})
    loop = TickRecorder(s.resource, resource_clock(s.resource), overrun_limit=10**6)
    loop.active = task
    task.activate()
    loop.run_for(0.3)  # moving
    r.inject(s.resource)()
    loop.executor.run(max_ticks=200)  # ticks go on (a stalled stream releases the loop itself)
    assert task.phase is Phase.FAULT
    assert [n for n in s.event_names() if ".T3." in n] == [f"MoveJoints.T3.{r.t3}"]
    ticks = loop.ticks()
    assert_safe_stop_in_time(ticks, status_shows(ticks, r.shows))
    assert_commands_within_limits(ticks, s.config)
