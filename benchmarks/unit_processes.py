"""Clock domains in processes of their own (issue 44, item 2): the unit processes themselves,
before they are wired into the daemon.

dual-arm-sim's two arms (`left` 1 kHz, `right` 500 Hz, each plant in its own process as in the
daemon), each in a unit process (`orccadd.daemon.unitproc`). This process stands in for the
automaton's: it loads a mission alternating a tracking law and a dwell on `right` and answers
each of right's postconditions with the other law (a switch request in the unit's channel,
taken at right's next tick). First both hold, then right switches: left's wake-up p99 in both
phases, read from its telemetry ring, is the isolation a process per domain gives here, beside
`benchmarks/station.py --runs dual,separate` (one daemon; two daemons).

Usage: `python benchmarks/unit_processes.py [--duration-s 20] [--rounds 1]` (root, for
SCHED_FIFO).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import select
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from harness import ROOT, figures
from station import SEPARATE_MISSION as MISSION

from orccadd.config.station import StationConfig
from orccadd.daemon.mission import compile_and_verify, prepare_mission
from orccadd.daemon.rtproc import TICK_RING_S
from orccadd.daemon.unit import hold_name, hold_task
from orccadd.daemon.unitlink import UnitLink
from orccadd.robot import backend_class, create_resource, load_station_config, station_as_run
from orccadd.task import EventQueue, EventRegistry, RobotTask
from orccadd.wire.schema import H, T
from orccadd.wire.telemetry import Layout, RingReader, TelemetryBlock
from tests.daemon.conftest import station_copy

DUAL = ROOT / "configs/robots/dual-arm-sim.toml"


def telemetry_for(station: StationConfig, i: int) -> TelemetryBlock:
    cfg = station.resources[i]
    signals = backend_class(cfg.resource.backend, cfg.source).describe(cfg).signals
    layout = Layout(cfg.dof, int(TICK_RING_S / cfg.control_period_s), 1, sum(g.size for g in signals))
    return TelemetryBlock.create(layout, cfg.control_period_s)


@contextlib.contextmanager
def units(
    path: Path, station: StationConfig, wake_w: int
) -> Iterator[tuple[list[UnitLink], list[TelemetryBlock]]]:
    tels = [telemetry_for(station, i) for i in range(len(station.resources))]
    links: list[UnitLink] = []
    try:
        for c, tel in zip(station.resources, tels, strict=True):
            links.append(UnitLink(path, c.resource.name, tel.name, wake_w))
        for link in links:
            link.wait_holding()
        yield links, tels
    finally:
        for link in links:
            link.end()
        for tel in tels:
            tel.close()


def _idle() -> None:
    pass


def record(
    readers: list[RingReader], duration_s: float, each: Callable[[], None] = _idle
) -> list[np.ndarray]:
    chunks: list[list[np.ndarray]] = [[] for _ in readers]
    end = time.monotonic() + duration_s
    while time.monotonic() < end:
        each()
        time.sleep(0.0 if each is not _idle else 0.2)
        for i, r in enumerate(readers):
            chunks[i].append(r.poll()[:, : len(T)])
    return [np.concatenate(c) for c in chunks]


def run(duration_s: float) -> list[str]:
    with tempfile.TemporaryDirectory(prefix="orccadd-units-") as tmp:
        path = station_copy(DUAL, Path(tmp), f'task_dirs = ["{ROOT}/configs/tasks"]')
        station = station_as_run(load_station_config(path), simulate=False, in_process_sim=False)
        mission = Path(tmp) / "right_switch.mission"
        mission.write_text(MISSION.format(tasks=ROOT / "configs/tasks"))
        registry = EventRegistry()
        shadows = {c.resource.name: create_resource(c) for c in station.resources}
        holds: list[RobotTask] = [
            hold_task(c, shadows[c.resource.name], registry, EventQueue(1), hold_name(True, c.resource.name))
            for c in station.resources
        ]
        wake_r, wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        try:
            with units(path, station, wake_w) as (links, tels):
                readers = [RingReader(t.ticks, t.header, H.TICK_HEAD) for t in tels]
                holding = record(readers, duration_s)
                automaton, report = compile_and_verify(mission)
                bindings = {n: (r, EventQueue(1)) for n, r in shadows.items()}
                loaded = prepare_mission(mission, automaton, report, bindings, registry)
                for link in links:
                    link.call(
                        "load",
                        path=str(mission),
                        automaton=automaton,
                        report=report,
                        specs=None,
                        events=registry.names(),
                    )
                tasks = [*holds, *loaded.tasks]
                track, dwell = (
                    next(i for i, t in enumerate(tasks) if t.name == n) for n in ("TrackR", "DwellR")
                )
                answer = {registry.id("TrackR.done"): dwell, registry.id("DwellR.done"): track}
                right = links[1].channel
                right.request_switch(track, fresh=False)
                switches = [0]

                def react() -> None:  # the automaton's part: right's events, answered
                    if select.select([wake_r], [], [], 0.05)[0]:
                        with contextlib.suppress(BlockingIOError):
                            os.read(wake_r, 4096)
                    for e in right.drain():
                        if e.event_id in answer:
                            right.request_switch(answer[e.event_id], fresh=False)
                            switches[0] += 1

                switching = record(readers, duration_s, react)
                right.request_switch(1, fresh=False)
        finally:
            os.close(wake_r)
            os.close(wake_w)
    out = []
    for label, ticks in (("both holding   ", holding), ("right switching", switching)):
        for name, t in zip(("left (1 ms)", "right (2 ms)"), ticks, strict=True):
            out.append(f"  {label} {name}: wake-up {figures(t[:, T.WAKE_US], 'µs')}")
    out.append(f"  right's law switches: {switches[0]}")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration-s", type=float, default=20.0, help="each phase")
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args()
    for k in range(args.rounds):
        print(f"round {k + 1}: dual-arm-sim's arms in two unit processes")
        for line in run(args.duration_s):
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
