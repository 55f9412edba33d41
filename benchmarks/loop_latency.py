"""Control-loop timing on the wall clock, against cyclictest in the same run.

Runs the sim-ur5e Ruckig + computed-torque task (configs/tasks/move_joints.toml) at
--period-ms (1 kHz by default) for --duration-s with SCHED_FIFO, cycling between targets; then
`cyclictest` (Debian rt-tests) at the same period and priority for the same duration, half just
before our loop and half just after (this VM's noise drifts within minutes: the baseline
brackets our run; both halves are printed). Prints
wake-up latency (median/p99/p99.9/max), compute time per tick (whole tick, and the part that
is `read()`: the plant simulation with --backend sim, a shared-memory copy with the default
--backend sim_process, where the plant runs in its own process), overruns and runs of
consecutive overruns, and the ratio of our wake-up p99 to cyclictest's. Run as root: `make bench`.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import numpy as np
from harness import cyclictest, targets_for

from orccadd.config.shipped import robot_config_path
from orccadd.robot import load_robot_config, with_backend
from orccadd.runtime import Summary, WallClock, enter_realtime, leave_realtime
from orccadd.session import Session
from orccadd.types import Phase

ROOT = Path(__file__).resolve().parent.parent
TARGETS = [
    [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0],
    [0.8, -1.2, 1.2, -1.6, -1.2, 0.4],
    [-0.5, -2.0, 2.2, -1.8, -1.57, -0.3],
]


def run_ours(
    period_s: float, duration_s: float, priority: int, spin_us: float, backend: str, cpu: int, robot: str,
    task_file: Path,
) -> dict[str, object]:  # fmt: skip
    cfg = load_robot_config(robot_config_path(robot))
    cfg = dataclasses.replace(cfg, control_period_s=period_s)
    plant_cpu = {"plant_cpu": 0 if cpu == 1 else -1} if backend == "sim_process" else {}
    cfg = with_backend(cfg, backend, **plant_cpu)
    s = Session.from_config(cfg)
    task = s.task(task_file)
    traj = next(m for m in task.modules if "target_rad" in m.parameters)
    m = s.resource.model
    goals = TARGETS if cfg.name == "ur5e" else targets_for(m.q_min_rad, m.q_max_rad, m.home_rad)
    loop = s.loop(WallClock(spin_margin_s=spin_us * 1e-6), overrun_limit=10**9)
    n_ticks = int(duration_s / period_s)
    plant_ns = np.zeros(n_ticks + 10, dtype=np.int64)
    res = s.resource
    inner_read = res.read
    perf = time.perf_counter_ns
    k = [0]

    def timed_read(t_s: float):  # type: ignore[no-untyped-def]
        t0 = perf()
        st = inner_read(t_s)
        plant_ns[k[0] % plant_ns.size] = perf() - t0
        k[0] += 1
        return st

    res.read = timed_read  # type: ignore[method-assign]
    target_i = [0]

    def step(t_s: float) -> None:
        task.tick(t_s)
        if task.phase is Phase.DONE:  # next target, re-armed inside the tick (cheap, no alloc)
            target_i[0] = (target_i[0] + 1) % len(goals)
            task.tune(f"{traj.name}.target_rad", goals[target_i[0]])
            task.activate()

    loop.executor.step = step
    traj.configure({"target_rad": goals[0]})
    loop.active = task
    task.activate()
    rt = enter_realtime(priority, cpus={cpu} if cpu >= 0 else None)
    try:
        loop.executor.run(max_ticks=n_ticks)
    finally:
        leave_realtime(rt)
        s.close()
    st = loop.stats
    return {
        "rt": rt,
        "latency": st.latency,
        "compute": st.compute,
        "plant": Summary.of(plant_ns[: min(k[0], plant_ns.size)]),
        "ticks": st.ticks,
        "overruns": st.overruns,
        "missed": st.missed_ticks,
        "max_run": st.max_consecutive_overruns,
        "runs": st.overrun_runs(),
        "phase": task.phase.name,
        "events": sorted(set(s.event_names())),
    }


def run_cyclictest(period_s: float, duration_s: float, priority: int) -> np.ndarray | None:
    """cyclictest's wake-up latencies in ns (None: not installed)."""
    samples_us = cyclictest(period_s, duration_s, priority)
    return None if samples_us is None else samples_us * 1000.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--robot", default="sim-ur5e", help="a simulated robot config (file or shipped name)")
    ap.add_argument("--task", type=Path, default=ROOT / "configs/tasks/move_joints.toml")
    ap.add_argument("--period-ms", type=float, default=1.0)
    ap.add_argument("--priority", type=int, default=80)
    ap.add_argument("--spin-us", type=float, default=150.0, help="wake this early and spin (0: pure sleep)")
    ap.add_argument(
        "--cpu",
        type=int,
        default=1 if (os.cpu_count() or 1) > 1 else -1,
        help="pin the control loop to this CPU (the plant process to CPU 0); -1: no pinning",
    )
    ap.add_argument(
        "--backend",
        default="sim_process",
        choices=["sim_process", "sim"],
        help="sim_process: the plant in its own process (as a real arm behind a bus); "
        "sim: the plant integrated inside read()",
    )
    args = ap.parse_args()
    period_s = args.period_ms * 1e-3
    before = run_cyclictest(period_s, args.duration_s / 2, args.priority)
    ours = run_ours(
        period_s, args.duration_s, args.priority, args.spin_us, args.backend, args.cpu, args.robot, args.task
    )
    after = run_cyclictest(period_s, args.duration_s / 2, args.priority)
    base = None if before is None or after is None else Summary.of(np.concatenate([before, after]))
    lat: Summary = ours["latency"]  # type: ignore[assignment]
    print(
        f"loop_latency: {args.robot} ({args.backend}) task {args.task.name}, {args.period_ms:g} ms, "
        f"{args.duration_s:g} s, {ours['rt'].describe()}, spin margin {args.spin_us:g} µs"
    )  # type: ignore[attr-defined]
    print(f"  wake-up latency   {lat.line()}")
    print(f"  compute per tick  {ours['compute'].line()}")  # type: ignore[attr-defined]
    print(f"   of which read()  {ours['plant'].line()}")  # type: ignore[attr-defined]
    print(
        f"  ticks {ours['ticks']}, overruns {ours['overruns']}, missed periods {ours['missed']}, "
        f"longest run of overruns {ours['max_run']}, runs by length {ours['runs']}"
    )
    if base is not None:
        print(f"  cyclictest        {base.line()}")
        assert before is not None and after is not None
        p99_before, p99_after = Summary.of(before).p99_us, Summary.of(after).p99_us
        print(f"    (p99 of the half before ours {p99_before:.0f} µs, of the half after {p99_after:.0f} µs)")
        ratio = lat.p99_us / base.p99_us if base.p99_us else float("inf")
        print(f"  ratio p99 ours/cyclictest = {ratio:.2f}  (target ≤ 1.0)")
    print(f"  task ended {ours['phase']}; events: {', '.join(ours['events']) or 'none'}")  # type: ignore[arg-type]
    print("  targets: compute p99 ≤ 100 µs, never 3 overruns in a row")
    if ours["phase"] in ("FAULT", "PRE_FAILED"):
        print(f"  INVALID: the task ended {ours['phase']}, so the figures above are not of the control law")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
