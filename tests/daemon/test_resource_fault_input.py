"""One resource, held by the daemon while the mission waits for its operator: its fault is the
mission's input `arm.fault`, which enters the safe procedure (before, the run went on and the
next task raised its type 3 on the stopped arm)."""

from __future__ import annotations

from pathlib import Path

from orccadd.automaton.compiler.automaton import SAFE
from orccadd.daemon.machine import Machine
from orccadd.types import Status
from orccadd.wire.schema import MissionResult
from tests.conftest import ROOT
from tests.daemon.conftest import load_in

MISSION = f"""
mission WaitGo
resource arm
input Go, Stop

task Reach on arm from "{ROOT}/configs/tasks/move_joints.toml"
  set traj.target_rad = [0.8, -1.2, 1.2, -1.6, -1.2, 0.4]
  post
end

main procedure Main
  handle
    await Go; Reach
  on fatal do
    safe
  end
end

safe procedure Acknowledge
  await Stop
end
"""


def test_a_fault_of_the_held_arm_enters_the_safe_procedure(machine: Machine, tmp_path: Path) -> None:
    path = tmp_path / "wait_go.mission"
    path.write_text(MISSION)
    loop = machine.default.loop
    load_in(machine, path)
    with machine.reactor.held():
        machine.command("start", {})
    loop.executor.run(max_ticks=5)
    assert loop.active is loop.hold  # the mission waits for Go: the arm on the daemon's Hold task
    res = machine.default.resource
    res.inject_fault("device", "test fault")
    loop.executor.run(max_ticks=2000, until=lambda: bool(res.state.status & Status.STOPPED))
    with machine.reactor.held():
        machine.on_events()
    mc = machine.mission
    assert mc.running and machine.default.supervisor.fault
    assert mc.mission is not None and mc.runner is not None
    state = mc.runner.number(mc.runner.snapshot())
    assert mc.mission.top.phase[state] == SAFE, mc.mission.top.where[state]  # entered on arm.fault
    with machine.reactor.held():
        machine.command("send", {"input": "Stop"})
    assert not mc.running and mc.result is MissionResult.SAFE, mc.result
