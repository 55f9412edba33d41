"""A resource's unit in a process of its own (issue 44, item 2), driven as the automaton's process
will drive it: started and holding, a mission's tasks built on both sides with the same event
ids (a difference refused), a law switched through shared memory and its events back through
the ring, a failed control thread told, and a safe stop at the end — asked for, or when the
automaton's side is gone."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from orccadd.config.station import StationConfig
from orccadd.daemon.mission import compile_and_verify, prepare_mission
from orccadd.daemon.rtproc import TICK_RING_S
from orccadd.daemon.unit import hold_name, hold_task
from orccadd.daemon.unitlink import UnitLink, UnitLinkError
from orccadd.robot import backend_class, create_resource, load_station_config, station_as_run
from orccadd.task import EventQueue, EventRegistry, RobotTask
from orccadd.wire.schema import H, T
from orccadd.wire.telemetry import Layout, TelemetryBlock
from tests.daemon.conftest import station_copy
from tests.ursim.conftest import wait_until

ROOT = Path(__file__).resolve().parents[2]
DUAL = ROOT / "configs/robots/dual-arm-sim.toml"
SWITCHING = ROOT / "benchmarks/missions/station_switching.mission"


@dataclass
class Automaton:
    """The automaton process's side of one unit, built here as the daemon will build it."""

    station: StationConfig
    link: UnitLink
    tel: TelemetryBlock
    registry: EventRegistry
    holds: list[RobotTask]
    wake_r: int

    def load(self, mission: Path, events: list[str] | None = None) -> list[RobotTask]:
        automaton, report = compile_and_verify(mission)
        bindings = {c.resource.name: (create_resource(c), EventQueue(1)) for c in self.station.resources}
        loaded = prepare_mission(mission, automaton, report, bindings, self.registry)
        self.link.call(
            "load",
            path=str(mission),
            automaton=automaton,
            report=report,
            specs=None,
            events=self.registry.names() if events is None else events,
        )
        return [*self.holds, *loaded.tasks]

    def task_on_unit(self) -> int:
        return int(self.tel.ticks[(int(self.tel.header[H.TICK_HEAD]) - 1) % len(self.tel.ticks), T.TASK])


@pytest.fixture
def unit(tmp_path: Path) -> Iterator[Automaton]:
    """The station dual-arm-sim; `right` (500 Hz) in a unit process, simulated in it."""
    path = station_copy(DUAL, tmp_path, f'task_dirs = ["{ROOT}/configs/tasks"]')
    station = station_as_run(load_station_config(path), simulate=False, in_process_sim=True)
    cfg = station.resources[1]
    signals = backend_class(cfg.resource.backend, cfg.source).describe(cfg).signals
    layout = Layout(cfg.dof, int(TICK_RING_S / cfg.control_period_s), 1, sum(g.size for g in signals))
    tel = TelemetryBlock.create(layout, cfg.control_period_s)
    registry = EventRegistry()
    holds = [
        hold_task(c, create_resource(c), registry, EventQueue(1), hold_name(True, c.resource.name))
        for c in station.resources
    ]
    wake_r, wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    link = UnitLink(path, "right", tel.name, wake_w, in_process_sim=True)
    os.close(wake_w)
    try:
        yield Automaton(station, link, tel, registry, holds, wake_r)
    finally:
        link.end()
        os.close(wake_r)
        tel.close()


def test_a_unit_process_holds_its_resource_with_the_automatons_event_ids(unit: Automaton) -> None:
    holding = unit.link.wait_holding()
    assert holding["tasks"] == ["Hold_left", "Hold_right"]
    assert holding["events"] == unit.registry.names()  # built in the same order on both sides
    assert holding["pid"] == unit.link.proc.pid
    ticks = int(unit.tel.header[H.TICKS])
    wait_until(lambda: int(unit.tel.header[H.TICKS]) > ticks + 50, 5.0, what="the unit's loop ticking")
    assert unit.task_on_unit() == 1  # Hold_right, by the automaton's task ids


def test_a_law_switched_through_shared_memory_reaches_the_unit_and_its_events_come_back(
    unit: Automaton,
) -> None:
    unit.link.wait_holding()
    tasks = unit.load(SWITCHING)
    track = next(i for i, t in enumerate(tasks) if t.name == "TrackR")
    request = unit.link.channel.request_switch(track, fresh=False)
    wait_until(lambda: unit.link.channel.switched(request), 5.0, what="the switch taken by a tick")
    wait_until(lambda: unit.task_on_unit() == track, 5.0, what="TrackR active on right")
    post = unit.registry.id("TrackR.done")
    events: list[int] = []

    def posted() -> bool:
        events.extend(e.event_id for e in unit.link.channel.drain())
        return post in events

    wait_until(posted, 10.0, what="TrackR's postcondition in the ring")
    assert os.read(unit.wake_r, 64)  # the automaton's process was woken
    back = unit.link.channel.request_switch(1, fresh=False)  # Hold_right again
    wait_until(lambda: unit.link.channel.switched(back) and unit.task_on_unit() == 1, 5.0, what="Hold")


def test_a_mission_whose_event_ids_differ_is_refused_by_the_unit(unit: Automaton) -> None:
    unit.link.wait_holding()
    with pytest.raises(UnitLinkError, match="event ids are not the automaton's"):
        unit.load(SWITCHING, events=["Hold_left.somewhere_else"])


def test_a_failed_control_thread_is_told_and_the_unit_exits_saying_so(unit: Automaton) -> None:
    unit.link.wait_holding()
    unit.link.call("inject", kind="control_thread")
    wait_until(
        lambda: any(m.get("op") == "failed" for m in unit.link.receive(0.05)),
        5.0,
        what="the unit telling its control thread failed",
    )
    assert "injected failure" in next(m["why"] for m in unit.link.seen if m.get("op") == "failed")
    assert unit.link.end() == 1  # safe-stopped by the dying thread, released; the failure in its code


def test_the_unit_safe_stops_and_exits_when_the_automatons_side_is_gone(unit: Automaton) -> None:
    unit.link.wait_holding()
    unit.link.sock.close()  # as if the automaton's process died
    end = time.monotonic() + 15.0
    while unit.link.proc.poll() is None and time.monotonic() < end:
        time.sleep(0.05)
    assert unit.link.proc.returncode == 0  # at rest, released
