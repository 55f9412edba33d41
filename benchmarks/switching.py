"""Law-switch latency on a running orccadd: event tick → first command of the new law.

Runs `orccadd` on sim-ur5e (500 Hz) with benchmarks/missions/switching.mission: Track (Ruckig +
computed torque) and Dwell (joint PD + gravity) alternate, each switch triggered by the
outgoing task's postcondition. The control thread takes the automaton's reaction in the tick of
the event and the new law commands that tick (`orccadd/daemon/inline.py`); when the automaton
thread is busy, it reacts itself and the switch comes at the next tick. A full-rate log (`log
start`, written by the command daemon from the shared-memory tick ring) gives, for each switch:

- latency in periods: index of the first tick of the new task minus index of the tick of the
  event (the automaton's instant in the log's events): 0 = in the event's tick, 1 = the next;
- latency in ms (the same on nominal release times, so periods skipped by an overrun count);
- the command gap: ticks without a command around the switch (target: none), and the longest
  interval between two consecutive commanded ticks over the whole run.

Usage: `python benchmarks/switching.py [--switches 1000]` (root for SCHED_FIFO; `make bench`).
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import time
from pathlib import Path

import numpy as np
from harness import ROOT, figures, running_daemon

from orccadd.ctl.client import Client

MISSION = ROOT / "benchmarks/missions/switching.mission"
SIGNALS = ["task", "phase", "wrote", "wake_us", "compute_us"]


def record(switches: int) -> tuple[Path, dict[str, object], list[str], float]:
    with running_daemon() as d, Client(d.socket, timeout_s=120) as c:
        c.call("load", path=str(MISSION))
        desc = c.call("describe")
        log = d.tmp / "switching.csv"
        c.call("log", action="start", signals=SIGNALS, name=f"switching-{os.getpid()}.csv")
        s0 = c.call("status")["switches"]
        c.call("start")
        t0 = time.monotonic()
        while True:
            s = c.call("status")
            if s["state"] != "running":
                raise SystemExit(f"the mission ended early ({s['result']}): {s['log']}")
            if s["switches"] - s0 >= switches + 2:
                break
            time.sleep(0.2)
        elapsed = time.monotonic() - t0
        c.call("stop")
        while c.call("status")["state"] == "running":
            time.sleep(0.05)
        time.sleep(0.1)
        info = c.call("log", action="stop")
        shutil.copyfile(info["file"], log)  # written in the daemon's log directory
        final = c.call("status")
        if info["lost"]:
            raise SystemExit(f"the log lost {info['lost']} tick records: figures would be wrong")
        return log, final, list(desc["tasks"]), elapsed


def analyse(log: Path, tasks: list[str], period_s: float, n_max: int) -> dict[str, object]:
    with log.open() as fh:
        lines = fh.read().splitlines()
    # the automaton's instants that answered a postcondition: the tick of the event
    events = [line[2:].split(",", 5) for line in lines if line.startswith("# event,")]
    ev_t = np.array(sorted(float(e[1]) for e in events if e[3] == "instant" and ".done" in e[4]))
    rows = list(csv.reader(line for line in lines if not line.startswith("#")))
    head, data = rows[0], np.array(rows[1:], dtype=float)
    col = {name: i for i, name in enumerate(head)}
    t, task = data[:, col["time_s"]], data[:, col["task"]]
    wrote = data[:, col["wrote"]]
    mission_ids = {tasks.index("Track"), tasks.index("Dwell")}
    lat_ticks, lat_ms, no_cmd = [], [], 0
    k = 1
    while k < len(task) and len(lat_ticks) < n_max:
        if task[k] != task[k - 1] and task[k - 1] in mission_ids and task[k] in mission_ids:
            i = int(np.searchsorted(ev_t, t[k] + 0.25 * period_s)) - 1  # the last event at or before
            if i >= 0:
                j = int(np.searchsorted(t, ev_t[i] - 0.25 * period_s))  # the event's tick
                lat_ticks.append(k - j)
                lat_ms.append((t[k] - t[j]) * 1e3)
                no_cmd += int((wrote[j : k + 1] == 0).sum())
        k += 1
    commanded = t[wrote > 0]
    gaps_ms = np.diff(commanded) * 1e3
    return {
        "ticks": lat_ticks,
        "ms": lat_ms,
        "no_cmd": no_cmd,
        "max_gap_ms": float(gaps_ms.max()) if gaps_ms.size else 0.0,
        "rows": len(t),
        "wake_us": data[:, col["wake_us"]],
        "compute_us": data[:, col["compute_us"]],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--switches", type=int, default=1000)
    args = ap.parse_args()
    log, final, tasks, elapsed = record(args.switches)
    period_s = 0.002
    r = analyse(log, tasks, period_s, args.switches)
    ticks = np.asarray(r["ticks"])
    print(
        f"switching: sim-ur5e, {period_s * 1e3:g} ms period, {len(ticks)} law switches "
        f"(Track <-> Dwell) in {elapsed:.1f} s, {r['rows']} ticks logged"
    )
    print(f"  event tick -> first command of the new law  {figures(ticks, 'periods', 2)}")
    print(f"  same on release times                      {figures(r['ms'], 'ms', 2)}")  # type: ignore[arg-type]
    share0 = float(np.mean(ticks == 0)) * 100 if ticks.size else 0.0
    share1 = float(np.mean(ticks == 1)) * 100 if ticks.size else 0.0
    print(
        f"  switches in the event's tick: {share0:.2f} %, on the next tick: {share1:.2f} % "
        f"(the automaton thread busy); ticks without a command around them: {r['no_cmd']}"
    )
    print(f"  longest interval between commands over the run: {r['max_gap_ms']:.2f} ms")
    print(f"  loop wake-up  {figures(r['wake_us'], 'µs')}")  # type: ignore[arg-type]
    print(f"  loop compute  {figures(r['compute_us'], 'µs')}")  # type: ignore[arg-type]
    print(f"  overruns {final['overruns']} over {final['ticks']} ticks; result {final['result']}")
    p99 = float(np.percentile(ticks, 99)) if ticks.size else float("inf")
    med = float(np.median(ticks)) if ticks.size else float("inf")
    print(f"  target: effect in the event's tick (0 periods) -> median {med:g}, p99 {p99:g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
