"""Where a task's tick goes: the cost of each module's update, of the resource's read and write,
and of the shell (preconditions, events, blending), per tick (median / p99 / max, µs).

Runs the task off real time on the simulated arm (`sim` backend: the plant is stepped inside
`read`, reported apart) for --ticks ticks, re-armed toward the next of three targets each time it
reaches one, so the profile covers motion and settling. Each module's `update` is timed on its own
(perf_counter_ns around the call: about 0.1 µs of the figure is the timer itself). So a user sees
which module eats the budget before putting a task on a robot:

    python benchmarks/tick_profile.py --robot sim-panda --task configs/tasks/move_joints.toml

A task whose trajectory is a tool's straight line (`offset_m`: move_line*.toml) is re-armed back
and forth along the base's x by --line-m instead of toward joint targets.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from harness import targets_for

from orccadd.config.robot import RobotConfig
from orccadd.config.shipped import robot_config_path
from orccadd.modules import Module
from orccadd.robot import load_robot_config, with_backend
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.types import Phase

ROOT = Path(__file__).resolve().parent.parent


def row(name: str, ns: np.ndarray) -> str:
    us = ns / 1e3
    return f"{name:28s} {np.median(us):9.2f} {np.percentile(us, 99):9.2f} {us.max():9.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="sim-ur5e", help="a robot config (file or shipped name)")
    ap.add_argument("--task", default=str(ROOT / "configs/tasks/move_joints.toml"))
    ap.add_argument("--ticks", type=int, default=20_000)
    ap.add_argument("--line-m", type=float, default=0.1, help="a line task's stroke (m)")
    args = ap.parse_args()

    cfg = with_backend(load_robot_config(robot_config_path(args.robot)), "sim")
    s = Session.from_config(cfg)
    task = s.task(Path(args.task))
    m = s.resource.model
    goals = goals_for(task, m.q_min_rad, m.q_max_rad, m.home_rad, args.line_m)
    traj = goal_module(task)

    n = args.ticks
    perf = time.perf_counter_ns
    per_module = {mod.name: np.zeros(n, dtype=np.int64) for mod in task.modules}
    tick_ns = np.zeros(n, dtype=np.int64)
    read_ns = np.zeros(n, dtype=np.int64)
    write_ns = np.zeros(n, dtype=np.int64)
    k = [0]

    def timed(name: str, update: Callable[[float], None]) -> Callable[[float], None]:
        out = per_module[name]

        def run(t_s: float) -> None:
            t0 = perf()
            update(t_s)
            out[k[0]] = perf() - t0

        return run

    task.compiled = None  # the interpreted path: each module's update timed on its own
    task.schedule = tuple(timed(mod.name, mod.update) for mod in task.modules)
    res = s.resource
    inner_read, inner_write = res.read, res.write

    def read(t_s: float):  # type: ignore[no-untyped-def]
        t0 = perf()
        st = inner_read(t_s)
        read_ns[k[0]] = perf() - t0
        return st

    def write(t_s: float, cmd: np.ndarray) -> int:
        t0 = perf()
        flags = inner_write(t_s, cmd)
        write_ns[k[0]] = perf() - t0
        return flags

    res.read = read  # type: ignore[method-assign]
    res.write = write  # type: ignore[method-assign]
    if traj is not None:
        traj.configure({goal_key(traj): goals[0]})
    task.activate()
    period = cfg.control_period_s
    goal = 0
    for i in range(n):
        k[0] = i
        t0 = perf()
        task.tick(i * period)
        tick_ns[i] = perf() - t0
        if task.phase is Phase.DONE and traj is not None:
            goal = (goal + 1) % len(goals)
            traj.configure({goal_key(traj): goals[goal]})  # between two runs: any goal, tunable or not
            task.activate()
        elif task.phase not in (Phase.RUN, Phase.PRE, Phase.DONE):
            raise SystemExit(f"the task ended {task.phase.name} at tick {i}: {task.fault_reason}")

    modules_ns = np.sum(list(per_module.values()), axis=0)
    shell_ns = tick_ns - read_ns - write_ns - modules_ns
    print(f"{cfg.name} ({cfg.dof} joints), task {task.name}, {n} ticks off real time (µs per tick)")
    print(f"{'':28s} {'median':>9s} {'p99':>9s} {'max':>9s}")
    for mod in task.modules:
        print(row(f"  {mod.name} ({mod.type_name})", per_module[mod.name]))
    print(row("  modules, together", modules_ns))
    print(row("  read (plant step inside)", read_ns))
    print(row("  write", write_ns))
    print(row("  shell (pre, events, blend)", shell_ns))
    print(row("tick", tick_ns))
    runs = [(c, law_times(cfg, Path(args.task), goals, n // 2, c)) for c in (False, True, False, True)]
    law = {c: np.concatenate([ns for cc, ns in runs if cc is c]) for c in (False, True)}
    print("the law (modules and shell events), interpreted against compiled, alternating runs:")
    print(row("  interpreted", law[False]))
    print(row("  compiled", law[True]))
    ratio = np.median(law[True]) / np.median(law[False])
    p99 = np.percentile(law[True], 99) / np.percentile(law[False], 99)
    print(f"  compiled / interpreted: median {ratio:.2f}, p99 {p99:.2f} (target ≤ 0.5)")


def law_times(
    cfg: RobotConfig, task_file: Path, goals: list[list[float]], n: int, compiled: bool
) -> np.ndarray:
    """`run_law`'s time per tick (ns) over `n` ticks of a fresh session, compiled or not."""
    s = Session.from_config(cfg)
    task = s.task(task_file)
    if not compiled:
        task.compiled = None
    traj = goal_module(task)
    out = np.zeros(n, dtype=np.int64)
    perf, inner, k = time.perf_counter_ns, task.run_law, [0]

    def run_law(t_s: float) -> None:
        t0 = perf()
        inner(t_s)
        out[k[0]] = perf() - t0

    task.run_law = run_law  # type: ignore[method-assign]
    if traj is not None:
        traj.configure({goal_key(traj): goals[0]})
    task.activate()
    goal = 0
    for i in range(n):
        k[0] = i
        task.tick(i * cfg.control_period_s)
        if task.phase is Phase.DONE and traj is not None:
            goal = (goal + 1) % len(goals)
            traj.configure({goal_key(traj): goals[goal]})  # between two runs: any goal, tunable or not
            task.activate()
    s.close()
    return out[out > 0]


GOAL_KEYS = ("target_rad", "offset_m")  # a joint trajectory's goal, a line's


def goal_module(task: RobotTask) -> Module | None:
    """The module whose goal re-arms the task: a joint trajectory or a line."""
    return next((mod for mod in task.modules if any(k in mod.parameters for k in GOAL_KEYS)), None)


def goal_key(module: Module) -> str:
    return next(k for k in GOAL_KEYS if k in module.parameters)


def goals_for(
    task: RobotTask, q_min: np.ndarray, q_max: np.ndarray, home: np.ndarray, line_m: float
) -> list[list[float]]:
    """The goals the task is re-armed toward in turn: joint targets, or a line back and forth."""
    traj = goal_module(task)
    if traj is not None and goal_key(traj) == "offset_m":
        return [[line_m, 0.0, 0.0], [-line_m, 0.0, 0.0]]
    return targets_for(q_min, q_max, home)


if __name__ == "__main__":
    main()
