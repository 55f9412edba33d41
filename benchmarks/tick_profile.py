"""Where a task's tick goes: the cost of each module's update, of the resource's read and write,
of the shell (preconditions, events, blending), of the telemetry record and of the executor,
per tick (median / p99 / max, µs), and the whole tick against the compiled law alone.

Runs the task off real time on the simulated arm (`sim` backend) for --ticks ticks, in the
daemon's control loop (`orccadd.daemon.loop.SwitchingLoop` on a `PeriodicExecutor`, with its
telemetry block), re-armed toward the next of three targets each time it reaches one, so the
profile covers motion and settling. The plant is stepped to each tick's release time between
two ticks, outside every figure, as a real arm moves while the loop sleeps (with `sim_process`
the plant runs in its own process): `read()` is the resource's own work (its copy and its limit
checks), not the physics. Garbage collection is off during the passes, as in the real-time
process.

Three kinds of pass, each on a fresh session:

- per module (the interpreted path): each module's `update` timed on its own, so a user sees
  which module eats the budget before putting a task on a robot;
- the parts of the tick (compiled law): `read()`, the law (`RobotTask.run_law`: the compiled
  modules and the shell's event tests), `write()`, the rest of the loop's `step` (the shell:
  switch and tune mailboxes, preconditions, blending, the task's bookkeeping), the telemetry
  record (`after_step`) and the executor's own work, timed apart (perf_counter_ns around each
  call: ~0.1 µs of each figure is the timer itself, and the executor's figure holds the timers
  of the others);
- the whole tick: the same loop without those timers, timed from one release to the next (all
  the control thread does per tick but sleep);

the last two alternating (twice each), and the interpreted law once more for the compiled /
interpreted ratio:

    python benchmarks/tick_profile.py --robot sim-panda --task configs/tasks/move_joints.toml

A task whose trajectory is a tool's straight line (`offset_m`: move_line*.toml) is re-armed back
and forth along the base's x by --line-m instead of toward joint targets.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from harness import targets_for

from orccadd.config.robot import RobotConfig
from orccadd.config.shipped import robot_config_path
from orccadd.daemon.loop import SwitchingLoop
from orccadd.modules import Module
from orccadd.physres.sim import SimulatedArm
from orccadd.robot import load_robot_config, with_backend
from orccadd.runtime.clock import Clock
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.types import Phase
from orccadd.wire.schema import Layout
from orccadd.wire.telemetry import TelemetryBlock

ROOT = Path(__file__).resolve().parent.parent
WARMUP = 200  # ticks left out of every figure (the first switch, first calls)
PARTS = ("read", "law", "write", "step", "telemetry")


def row(name: str, ns: np.ndarray) -> str:
    us = ns / 1e3
    return f"{name:34s} {np.median(us):9.2f} {np.percentile(us, 99):9.2f} {us.max():9.2f}"


class BetweenTicks(Clock):
    """Simulated time for the executor, and what happens between two ticks off every figure
    (`between(t_s)`: the plant stepped to the release, the task re-armed). Stamps each tick
    from its release to the next wait (`tick_ns`); `k` is the tick being run."""

    def __init__(self, n: int, between: Callable[[float], None]) -> None:
        self._now_ns = 0
        self.between = between
        self.tick_ns = np.zeros(n, dtype=np.int64)
        self.k = -1
        self._start = 0

    def now_ns(self) -> int:
        return self._now_ns

    def sleep_until_ns(self, deadline_ns: int) -> None:
        self._now_ns = max(self._now_ns, deadline_ns)

    def wait_release_ns(self, deadline_ns: int) -> int:
        end = time.perf_counter_ns()
        if self.k >= 0:
            self.tick_ns[self.k] = end - self._start
        self.sleep_until_ns(deadline_ns)
        self.between(deadline_ns * 1e-9)
        self.k += 1
        self._start = time.perf_counter_ns()
        return deadline_ns


@dataclass
class Pass:
    """One pass's figures (ns per tick, warm-up left out)."""

    tick: np.ndarray
    parts: dict[str, np.ndarray]
    modules: dict[str, np.ndarray]


@contextlib.contextmanager
def gc_off() -> Iterator[None]:
    """As the real-time process runs its loop (`orccadd.runtime.rt`): gc frozen and disabled."""
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
        gc.unfreeze()


def run_pass(cfg: RobotConfig, task_file: Path, goals: list[list[float]], n: int, kind: str) -> Pass:
    """`n` ticks of the task in a fresh session's `SwitchingLoop`. `kind`: "modules" (interpreted,
    each module timed), "parts" or "parts-interpreted" (read, law, write, step, telemetry timed),
    "whole" (no timer but the clock's)."""
    s = Session.from_config(cfg)
    res = s.resource
    assert isinstance(res, SimulatedArm)
    task = s.task(task_file)
    traj = goal_module(task)
    extra = sum(g.size for g in res.description.signals)
    tel = TelemetryBlock.create(Layout(cfg.dof, 8000, 1000, extra), cfg.control_period_s)
    wake_r, wake_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    goal = [0]

    def between(t_s: float) -> None:
        if task.phase is Phase.DONE and traj is not None:
            goal[0] = (goal[0] + 1) % len(goals)
            traj.configure({goal_key(traj): goals[goal[0]]})  # between two runs: any goal
            task.activate()
        elif task.phase not in (Phase.IDLE, Phase.RUN, Phase.PRE, Phase.DONE):
            raise SystemExit(f"the task ended {task.phase.name} at t = {t_s:.3f} s: {task.fault_reason}")
        if res.t_sim_s is not None:
            res._advance_to(t_s)  # the plant moves while the loop sleeps: read() only copies
        s.queue.drain()
        with contextlib.suppress(BlockingIOError):
            os.read(wake_r, 4096)

    size = n + WARMUP + 1  # the tick after the last one stamped runs too
    clock = BetweenTicks(size, between)
    blend = int(round(cfg.daemon.switch_blend_s / cfg.control_period_s))
    loop = SwitchingLoop(res, clock, task, s.queue, tel, wake_w, overrun_limit=10**9, blend_ticks=blend)
    parts = {p: np.zeros(size, dtype=np.int64) for p in PARTS} if kind.startswith("parts") else {}
    modules = {m.name: np.zeros(size, dtype=np.int64) for m in task.modules} if kind == "modules" else {}
    if kind in ("modules", "parts-interpreted"):
        task.compiled = None  # the interpreted path
    if modules:
        task.schedule = tuple(timed(mod.update, modules[mod.name], clock) for mod in task.modules)
    if parts:
        res.read = timed(res.read, parts["read"], clock)  # type: ignore[method-assign]
        res.write = timed(res.write, parts["write"], clock)  # type: ignore[method-assign]
        task.run_law = timed(task.run_law, parts["law"], clock)  # type: ignore[method-assign]
        ex = loop.executor
        ex.step = timed(ex.step, parts["step"], clock)
        assert ex.after_step is not None
        ex.after_step = timed(ex.after_step, parts["telemetry"], clock)
    if traj is not None:
        traj.configure({goal_key(traj): goals[0]})
    try:
        with gc_off():
            loop.executor.run(max_ticks=size)  # a tick's stamp is taken as the next one is released
    finally:
        loop.close()
        tel.close()
        s.close()
        os.close(wake_r)
        os.close(wake_w)
    keep = slice(WARMUP, n + WARMUP)
    return Pass(
        clock.tick_ns[keep],
        {k: v[keep] for k, v in parts.items()},
        {k: v[keep] for k, v in modules.items()},
    )


def timed(call: Callable[..., Any], out: np.ndarray, clock: BetweenTicks) -> Callable[..., Any]:
    """`call`, its time per tick added into `out[clock.k]`."""
    perf = time.perf_counter_ns

    def run(*args: Any) -> Any:
        t0 = perf()
        r = call(*args)
        out[clock.k] += perf() - t0
        return r

    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="sim-ur5e", help="a robot config (file or shipped name)")
    ap.add_argument("--task", default=str(ROOT / "configs/tasks/move_joints.toml"))
    ap.add_argument("--ticks", type=int, default=20_000, help="ticks of each kind of pass")
    ap.add_argument("--line-m", type=float, default=0.1, help="a line task's stroke (m)")
    args = ap.parse_args()

    cfg = with_backend(load_robot_config(robot_config_path(args.robot)), "sim")
    task_file = Path(args.task)
    s = Session.from_config(cfg)
    task = s.task(task_file)
    m = s.resource.model
    goals = goals_for(task, m.q_min_rad, m.q_max_rad, m.home_rad, args.line_m)
    s.close()
    n = args.ticks
    half = n // 2

    per_module = run_pass(cfg, task_file, goals, n, "modules")
    runs = [run_pass(cfg, task_file, goals, half, k) for k in ("parts", "whole", "parts", "whole")]
    interpreted = [run_pass(cfg, task_file, goals, half, "parts-interpreted") for _ in range(2)]
    parts = {p: np.concatenate([r.parts[p] for r in runs if r.parts]) for p in PARTS}
    parts_tick = np.concatenate([r.tick for r in runs if r.parts])
    whole = np.concatenate([r.tick for r in runs if not r.parts])
    law = parts["law"]

    print(f"{cfg.name} ({cfg.dof} joints), task {task.name}, off real time (µs per tick)")
    print(f"{'':34s} {'median':>9s} {'p99':>9s} {'max':>9s}")
    print(f"each module's update (interpreted, {n} ticks):")
    for mod in task.modules:
        print(row(f"  {mod.name} ({mod.type_name})", per_module.modules[mod.name]))
    print(row("  modules, together", np.sum(list(per_module.modules.values()), axis=0)))
    print(f"the tick in the control loop (compiled law, {2 * half} ticks, parts timed apart):")
    print(row("  read()", parts["read"]))
    print(row("  the law (compiled, events)", law))
    print(row("  write() (limits, guard)", parts["write"]))
    print(row("  shell (mailboxes, pre, blend)", parts["step"] - parts["read"] - law - parts["write"]))
    print(row("  telemetry record", parts["telemetry"]))
    print(row("  executor (and the timers)", parts_tick - parts["step"] - parts["telemetry"]))
    print(row(f"whole tick (no part timed, {whole.size} ticks)", whole))
    ratio = np.median(whole) / np.median(law)
    p99 = np.percentile(whole, 99) / np.percentile(law, 99)
    print(f"  whole tick / law: median {ratio:.2f}, p99 {p99:.2f} (target ≤ 2)")
    interp = np.concatenate([r.parts["law"] for r in interpreted])
    print("the law, interpreted against compiled:")
    print(row("  interpreted", interp))
    print(row("  compiled", law))
    ratio = np.median(law) / np.median(interp)
    p99 = np.percentile(law, 99) / np.percentile(interp, 99)
    print(f"  compiled / interpreted: median {ratio:.2f}, p99 {p99:.2f} (target ≤ 0.5)")


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
