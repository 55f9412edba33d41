"""A switch to Hold on an arm moving at speed in position mode (servoJ, CSP): the Hold task brings
the command to rest within the joints' acceleration limits and holds where it stopped, rather than
pulling the command back to where the arm is measured (a step that braked a UR's elbow beyond its
controller's limit: a protective stop). Simulated arm and simulated time: deterministic."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from orccadd.daemon.machine import Machine
from orccadd.robot import load_robot_config, with_backend
from orccadd.runtime.clock import SimClock
from orccadd.types import CommandMode
from orccadd.wire.schema import H, T, TickLayout
from tests.daemon.conftest import ROBOT, ROOT, load_in, machine_on

MISSION = f"""mission Reach
resource arm
input Stop

task Reach on arm from "{ROOT}/configs/tasks/move_joints_csp.toml"
  set traj.target_rad = [1.2, -0.6, 0.4, -0.6, -0.6, 1.2]
  post
end

main procedure Main
  handle
    Reach
  on fatal do
    safe
  end
end

safe procedure Stopped
  await Stop
end
"""


@pytest.fixture
def csp_machine(tmp_path: Path) -> Iterator[Machine]:
    """sim-ur5e in position mode, its Hold task hold_csp.toml, on simulated time; a test ticks it."""
    cfg = with_backend(load_robot_config(ROBOT), "sim")
    hold = str(ROOT / "configs/tasks/hold_csp.toml")
    cfg = replace(cfg, daemon=replace(cfg.daemon, hold_task=hold, mission_dirs=(str(tmp_path),)))
    with machine_on(cfg, CommandMode.POSITION, SimClock()) as m:
        yield m


def tick(machine: Machine, ticks: int = 1) -> None:
    for _ in range(ticks):
        machine.default.loop.executor.run(max_ticks=1)
        with machine.reactor.held():
            machine.on_events()


def commands(machine: Machine) -> npt.NDArray[np.float64]:
    """The command of every tick so far (the telemetry ring has not wrapped)."""
    recs = machine.default.tel.ticks[: int(machine.default.tel.header[H.TICK_HEAD])]
    return np.array(recs[:, TickLayout(machine.default.tel.dof).cmd])


def test_hold_brings_a_fast_position_command_to_rest_within_the_acceleration_limits(
    csp_machine: Machine, tmp_path: Path
) -> None:
    m = csp_machine
    res, loop = m.default.resource, m.default.loop
    path = tmp_path / "reach.mission"
    path.write_text(MISSION)
    load_in(m, path)
    with m.reactor.held():
        m.command("start", {})
    for _ in range(5000):  # until the arm moves fast (the trajectory cruises at 0.8 of the limit)
        tick(m)
        if np.abs(res.state.dq_rad_s).max() > 1.0:
            break
    speed_rad_s = float(np.abs(res.state.dq_rad_s).max())
    assert speed_rad_s > 1.0 and loop.active is not loop.hold
    switch_tick = int(m.default.tel.header[H.TICK_HEAD])
    with m.reactor.held():
        m.command("hold", {})
    for _ in range(5000):  # until the arm is at rest on the Hold task, its command too
        tick(m)
        if loop.active is loop.hold and np.abs(res.state.dq_rad_s).max() < 1e-3:
            last = commands(m)[-2:]
            if (last[0] == last[1]).all():
                break
    assert loop.active is loop.hold
    assert np.abs(res.state.dq_rad_s).max() < 1e-3, res.state.dq_rad_s
    tick(m, 50)

    period_s = res.config.control_period_s
    cmd = commands(m)
    recs = m.default.tel.ticks[: int(m.default.tel.header[H.TICK_HEAD])]
    assert recs[:, T.WROTE].all()  # a fresh command every tick, through the switch
    around = cmd[switch_tick - 5 :]
    ddq = np.diff(around, n=2, axis=0) / period_s**2  # the commanded acceleration, tick by tick
    a_max = res.model.a_max_rad_s2
    peak = np.abs(ddq).max(axis=0)
    assert (peak <= a_max * 1.001).all(), f"commanded acceleration {peak} beyond {a_max} rad/s^2"
    assert np.abs(np.diff(cmd[-50:], axis=0)).max() == 0.0  # held: the command stands still
    assert np.abs(res.state.q_rad - cmd[-1]).max() < 0.01  # where the arm rests
