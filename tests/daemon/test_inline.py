"""The law switch in the tick of its event (`InlineReactor`), and the fallback one tick later.

The loop is ticked here one tick at a time; between ticks the test plays the automaton thread
(`reactor.held()` then `on_events`, as the real-time process does). A mission alternates Track
and Dwell, each ended by its postcondition: every switch is read back from the telemetry ring.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orccadd.daemon.machine import Machine
from orccadd.types import Phase
from orccadd.wire.schema import H, R, T, Trace
from tests.daemon.conftest import ROOT, load_in

MISSION = (ROOT / "benchmarks/missions/switching.mission").read_text()


def load_and_start(machine: Machine, tmp: Path) -> None:
    path = tmp / "switching.mission"  # the benchmark's mission, its task files found from here
    path.write_text(MISSION.replace('"../../configs/', f'"{ROOT}/configs/'))
    load_in(machine, path)
    with machine.reactor.held():
        machine.command("start", {})


@dataclass
class Switch:
    tick: int  # index of the first tick whose record shows the new task
    event_tick: int  # index of the tick the outgoing task raised its postcondition in
    wrote: bool  # a command was sent in every tick from the event to the switch


def switches(machine: Machine) -> list[Switch]:
    """Every Track <-> Dwell switch the ring holds, with the tick of its event."""
    tel = machine.default.tel
    recs = tel.ticks[: int(tel.header[H.TICK_HEAD])]  # the ring has not wrapped
    task, phase, wrote = recs[:, T.TASK], recs[:, T.PHASE], recs[:, T.WROTE]
    ids = {machine.mission.tasks().index(t) for t in machine.mission.tasks() if t.name in ("Track", "Dwell")}
    out = []
    for k in range(1, len(task)):
        if task[k] != task[k - 1] and task[k] in ids and task[k - 1] in ids:
            j = k - 1 if phase[k - 1] == Phase.DONE else k  # the outgoing task seen done: a tick late
            out.append(Switch(k, j, bool(wrote[j : k + 1].all())))
    return out


def instant_times(machine: Machine) -> list[float]:
    trace = machine.pub.tel.trace
    rows = trace[(trace[:, R.SEQ] > 0) & (trace[:, R.KIND] == Trace.INSTANT)]
    return sorted(float(t) for t in rows[:, R.T_S])


def run(machine: Machine, ticks: int, busy: bool) -> None:
    """Tick the loop; `busy`: the automaton thread holds its lock through every tick (it is
    handling a command, say), so the control thread cannot react in the tick."""
    for _ in range(ticks):
        if busy:
            with machine.reactor.held():
                machine.default.loop.executor.run(max_ticks=1)
                machine.on_events()
        else:
            machine.default.loop.executor.run(max_ticks=1)
            with machine.reactor.held():
                machine.on_events()


def test_the_new_law_commands_the_tick_of_the_event(machine: Machine, tmp_path: Path) -> None:
    load_and_start(machine, tmp_path)
    run(machine, 600, busy=False)
    seen = switches(machine)
    assert len(seen) >= 6, f"only {len(seen)} switches in 600 ticks"
    assert all(s.tick == s.event_tick for s in seen), [(s.tick, s.event_tick) for s in seen]
    assert all(s.wrote for s in seen)  # the new law's command went out in the event's tick
    ticks_t = machine.default.tel.ticks[: int(machine.default.tel.header[H.TICK_HEAD]), T.T_S]
    instants = set(instant_times(machine))
    # the automaton's instant is recorded at the event's tick, which the new task commanded
    kept = [float(ticks_t[s.tick]) for s in seen if ticks_t[s.tick] >= min(instants)]  # the trace ring's
    assert len(kept) > 50 and set(kept) <= instants
    assert machine.reactor.inline >= len(seen)
    assert machine.mission.instants >= len(seen)  # booked by the automaton thread afterwards


def test_with_the_automaton_thread_busy_the_switch_comes_one_tick_later(
    machine: Machine, tmp_path: Path
) -> None:
    load_and_start(machine, tmp_path)
    run(machine, 600, busy=True)
    seen = switches(machine)
    assert len(seen) >= 6, f"only {len(seen)} switches in 600 ticks"
    assert all(s.tick == s.event_tick + 1 for s in seen), [(s.tick, s.event_tick) for s in seen]
    assert all(s.wrote for s in seen)  # the outgoing law held its last command meanwhile
    assert machine.reactor.inline == 0


def test_a_stop_while_running_ends_the_run_the_same_way(machine: Machine, tmp_path: Path) -> None:
    load_and_start(machine, tmp_path)
    run(machine, 500, busy=False)
    with machine.reactor.held():
        machine.command("send", {"input": "Stop"})
    run(machine, 50, busy=False)
    assert machine.mission.state.name == "READY" and machine.mission.result.name == "SUCCESS"
    assert machine.default.loop.active is machine.default.loop.hold
    assert np.isfinite(machine.default.resource.last_command).all()
