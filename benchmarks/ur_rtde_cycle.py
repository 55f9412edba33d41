"""A UR arm over RTDE at 500 Hz (the `ur_rtde` backend, servoJ) against the simulated controller:
our tick and the controller's cycle, the wake-up on a package, command-to-motion latency, the
servoJ updates the controller missed; cyclictest in the same run.

Starts the UR controller simulator (`python -m orccadd.ursim`, ur5e-rtde-sim, booted running, at
SCHED_FIFO --sim-priority as the tests run it), opens the `ur_rtde` backend on it (stock ur_rtde,
its threads at the config's rtde_priority) and runs orccadd's control loop on the controller's
stream (device-paced: a new RTDE package releases each tick) at SCHED_FIFO --priority with memory
locked, as the daemon's control thread: Ruckig position tasks (configs/tasks/move_joints_csp.toml
at SPEED_SCALE) back and forth between two poses, every tick's position sent by servoJ with the
configured lookahead_time and gain; --duration-s measured after WARMUP_S. cyclictest (rt-tests)
at the same period and priority, half of --duration-s just before our loop and half just after
(the simulator running, no client), is the baseline. Prints median / p99 / max of:

- our tick release period and its jitter (|period - 2 ms|) on CLOCK_MONOTONIC;
- the controller's timestamp steps between the packages our ticks read: a cycle we did not see
  is a packet missed (the backend's `packets_missed`), told apart into cycles the simulator
  skipped itself, packages its sender replaced unsent, and the rest (ur_rtde's thread or ours);
- wake-up latency: ur_rtde runs in the link process (`drivers.ur.link_server`), whose stream
  thread reads the controller's RTDE stream by a blocking read (`drivers.ur.rtde_stream`) and
  sends each package to us; the tick's release is the instant that read returned, and the
  wake-up is from there to our control thread running (the hop between the two processes
  included), judged against cyclictest's p99. Also the package's age at release (since its
  cycle's start: the simulator's wake-up, its cycle, its sender, loopback TCP, the link
  process's read);
- our tick's compute (release -> servoJ sent), and when the servoJ left, since the cycle of
  the package it answers: after the next cycle's start it can only reach the one after;
- command-to-motion latency, on the controller's time (each command at its package's cycle,
  the actual position at its own): the shift that best aligns actual on commanded positions
  (least squares, each moving joint), and per move the delay between commanded and actual
  crossing the middle of the move (its leading joint);
- servoJ updates the controller missed: its cycles of a running servoj with no new input
  package since the cycle before, and packages written over unread (counted by the simulator).

Targets: no missed controller cycles over 60 s (no package unseen, no servoj cycle without a
new command); our wake-up p99 <= cyclictest's p99 in the same run. Usage: `python
benchmarks/ur_rtde_cycle.py [--duration-s 60]` (root for SCHED_FIFO; Ctrl-C stops it cleanly:
ur_rtde disconnected, then the simulator stopped).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from importlib.metadata import version
from textwrap import indent
from typing import Any

import numpy as np
from harness import ROOT, cyclictest, figures

from orccadd.daemon.rtproc import GIL_SWITCH_INTERVAL_S
from orccadd.physres.base import PhysicalResource
from orccadd.physres.ur_rtde import UrRtdeArm
from orccadd.robot import create_resource, load_robot_config
from orccadd.runtime import enter_realtime, leave_realtime
from orccadd.runtime.clock import Clock
from orccadd.session import Session
from orccadd.task import RobotTask
from orccadd.task.loop import ControlLoop, resource_clock
from orccadd.types import CommandMode, Phase
from orccadd.ursim.process import UrSimProcess

CONFIG = ROOT / "configs/robots/ur5e-rtde-sim.toml"
MOVE = ROOT / "configs/tasks/move_joints_csp.toml"
POSES = (  # the backend tests' HOME and REACH: up to 0.5 rad a joint
    [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0],
    [0.5, -1.3, 1.3, -1.6, -1.3, 0.3],
)
# Ruckig at 0.3 of the joint limits (1.8 rad/s² on the big joints): a command late by a few
# cycles, then caught up in one, steps the servo's target; the controller protective-stops a
# servoj target past a joint's acceleration limit (6 rad/s²), which at 0.5 this VM's late ticks
# reached now and then
SPEED_SCALE = 0.3
WARMUP_S = 1.0  # ticked before the measured window (first packages, first plan)
MAX_LAG_S = 0.5  # command-to-motion: shifts tried
MOVING_RAD = 0.1  # a joint is in the lag fit if it moves at least this far


@dataclass
class Record:
    """Per tick of the measured window, preallocated (nothing allocated in a tick)."""

    n: int
    dof: int
    k: int = 0
    release_ns: np.ndarray = field(init=False)
    stamp_s: np.ndarray = field(init=False)  # the controller's timestamp of the package read
    wake_ns: np.ndarray = field(init=False)  # the package seen by the link process -> our thread runs
    sent_ns: np.ndarray = field(init=False)  # the tick's end: its servoJ sent
    q_cmd: np.ndarray = field(init=False)
    q_act: np.ndarray = field(init=False)
    moves: list[tuple[int, int]] = field(default_factory=list)  # (first tick, pose index)

    def __post_init__(self) -> None:
        n, dof = self.n, self.dof
        self.release_ns = np.zeros(n, dtype=np.int64)
        self.stamp_s = np.zeros(n)
        self.wake_ns = np.zeros(n, dtype=np.int64)
        self.sent_ns = np.zeros(n, dtype=np.int64)
        self.q_cmd = np.zeros((n, dof))
        self.q_act = np.zeros((n, dof))

    def trim(self) -> None:
        """Keep the ticks recorded (a run cut short)."""
        k = self.k
        for name in ("release_ns", "stamp_s", "wake_ns", "sent_ns", "q_cmd", "q_act"):
            setattr(self, name, getattr(self, name)[:k])
        self.n = k


class BackAndForth(ControlLoop):
    """orccadd's control loop ticking a move_joints_csp task, re-armed toward the other pose
    inside the tick that ends a move (as benchmarks/loop_latency.py), recording each tick."""

    def __init__(self, resource: PhysicalResource, clock: Clock, task: RobotTask, rec: Record) -> None:
        super().__init__(resource, clock, overrun_limit=10**9)
        self.task, self.rec = task, rec
        self.pose = 1
        self.recording = False
        self.rearm = True  # False: the last move, ending at rest
        self.ended = ""  # why the task stopped moving (T2, T3), if it did

    def step(self, t_s: float) -> None:
        task = self.task
        task.tick(t_s)
        if task.phase is Phase.DONE and self.rearm:
            self.pose = 1 - self.pose
            task.tune("traj.target_rad", POSES[self.pose])
            task.activate()
            if self.recording:
                self.rec.moves.append((self.rec.k + 1, self.pose))
        elif task.phase in (Phase.ABORTED, Phase.FAULT, Phase.PRE_FAILED):
            self.ended = task.phase.name
            self.executor.stop()

    def after_step(self, t_s: float) -> None:
        sent = time.monotonic_ns()
        rec = self.rec
        if not self.recording or rec.k >= rec.n:
            return
        k, res = rec.k, self.resource
        assert isinstance(res, UrRtdeArm)
        pkg = res.link.state
        assert pkg is not None
        rec.release_ns[k] = round(t_s * 1e9)
        rec.stamp_s[k] = pkg.stamp
        rec.wake_ns[k] = self.stats.last_latency_ns  # the release is the package's arrival
        rec.sent_ns[k] = sent
        rec.q_cmd[k] = res.last_command
        rec.q_act[k] = res.state.q_rad
        rec.k = k + 1
        if rec.k == rec.n:
            self.executor.stop()


def status_while_ticking(loop: BackAndForth, sim: UrSimProcess) -> dict[str, Any]:
    """The simulator's status, asked from a helper thread while the loop keeps ticking (the
    servoJ stream must not pause: a pause would count as missed updates)."""
    out: dict[str, Any] = {}
    done = threading.Event()

    def ask() -> None:
        try:
            out.update(sim.status())
        finally:
            done.set()

    threading.Thread(target=ask, name="ursim-status", daemon=True).start()
    end = time.monotonic() + 10.0
    while not done.is_set() and not loop.ended and time.monotonic() < end:
        loop.executor.run(until=lambda: done.is_set() or time.monotonic() > end)
    if not done.wait(max(0.0, end - time.monotonic())) or not out:
        raise RuntimeError("the simulator's status did not come within 10 s")
    return out


@dataclass
class Run:
    rec: Record
    rt: str
    ticks: int
    overruns: int
    missed_periods: int
    packets_missed: int
    s0: dict[str, Any]
    s1: dict[str, Any]
    lookahead_s: float
    gain: float
    ended: str
    fault: str
    events: list[str]
    sim_log: str = ""  # the simulator's warnings and errors


def run_ours(sim: UrSimProcess, duration_s: float, priority: int) -> Run:
    cfg = load_robot_config(CONFIG)
    # Session.open's steps, with the task built before the resource is configured: the first
    # tick follows the connection at once (the controller's RTDE watchdog, the stall check)
    s = Session(cfg, create_resource(cfg))
    arm = s.resource
    assert isinstance(arm, UrRtdeArm)
    period = cfg.control_period_s
    rec = Record(int(round(duration_s / period)), cfg.dof)
    task = s.task(MOVE)
    traj = next(m for m in task.modules if m.name == "traj")
    traj.configure({"target_rad": POSES[1], "speed_scale": SPEED_SCALE})
    loop = BackAndForth(arm, resource_clock(arm), task, rec)
    stats = loop.stats
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)  # as the daemon
    rt = enter_realtime(priority)  # memory locked before the controller waits for us
    try:  # ur_rtde's clients go (s.close) before the simulator does
        arm.configure()
        arm.activate(CommandMode.POSITION)
        loop.active = task
        task.activate()
        loop.executor.run(max_ticks=int(round(WARMUP_S / period)))
        s0 = status_while_ticking(loop, sim)
        missed0, st0 = arm.packets_missed, (stats.ticks, stats.overruns, stats.missed_ticks)
        rec.moves.append((0, loop.pose))  # the move under way when recording starts
        loop.recording = True
        while not loop.ended and rec.k < rec.n:
            loop.executor.run()  # until the record is full (or the task stops moving)
        loop.recording = False
        missed1, st1 = arm.packets_missed, (stats.ticks, stats.overruns, stats.missed_ticks)
        s1 = status_while_ticking(loop, sim)
        loop.rearm = False  # finish the move under way: ur_rtde closes with the arm at rest
        loop.executor.run(max_ticks=int(10.0 / period), until=lambda: task.phase is not Phase.RUN)
    finally:
        leave_realtime(rt)
        fault = arm.fault_message
        s.close()
    rec.trim()
    return Run(
        rec=rec,
        rt="; ".join([rt.describe(), *rt.warnings]),
        ticks=st1[0] - st0[0],
        overruns=st1[1] - st0[1],
        missed_periods=st1[2] - st0[2],
        packets_missed=missed1 - missed0,
        s0=s0,
        s1=s1,
        lookahead_s=arm.settings.lookahead_time_s,
        gain=arm.settings.gain,
        ended=loop.ended,
        fault=fault,
        events=sorted(set(s.event_names())),
    )


# ---- analysis ---------------------------------------------------------------------------------
def lag_fit(t: np.ndarray, cmd: np.ndarray, act: np.ndarray, period: float) -> dict[int, float]:
    """Per moving joint, the shift τ (s) minimising Σ (act(t) − cmd(t − τ))², on a uniform grid of
    the controller's time (integer cycles, then a parabola through the three around the best)."""
    if t.size < 2:
        return {}
    grid = np.arange(t[0], t[-1], period)
    lags = np.arange(int(MAX_LAG_S / period) + 1)
    out: dict[int, float] = {}
    for j in range(cmd.shape[1]):
        if np.ptp(cmd[:, j]) < MOVING_RAD:
            continue
        c, a = np.interp(grid, t, cmd[:, j]), np.interp(grid, t, act[:, j])
        m = grid.size - lags[-1]
        if m < 10:
            continue
        err = np.array([np.mean((a[lag : lag + m] - c[:m]) ** 2) for lag in lags])
        i = int(np.argmin(err))
        frac = 0.0
        if 0 < i < lags[-1]:
            e0, e1, e2 = err[i - 1], err[i], err[i + 1]
            den = e0 - 2 * e1 + e2
            frac = 0.5 * (e0 - e2) / den if den > 0 else 0.0
        out[j] = (i + frac) * period
    return out


def crossing(t: np.ndarray, x: np.ndarray, level: float) -> float | None:
    """The first time `x` crosses `level` (linear between samples), None if it does not."""
    side = np.sign(x - level)
    idx = np.nonzero(side[1:] != side[0])[0]
    if not idx.size or side[0] == 0:
        return None
    i = int(idx[0]) + 1
    x0, x1 = x[i - 1], x[i]
    return float(t[i - 1] + (t[i] - t[i - 1]) * ((level - x0) / (x1 - x0) if x1 != x0 else 0.0))


def move_delays(rec: Record) -> list[float]:
    """Per complete move: actual minus commanded time of crossing the middle of the move on the
    leading joint (ms), on the controller's time."""
    out: list[float] = []
    bounds = [*[m[0] for m in rec.moves], rec.n]
    for (first, pose), end in zip(rec.moves, bounds[1:], strict=True):
        a, b = np.array(POSES[1 - pose]), np.array(POSES[pose])
        j = int(np.argmax(np.abs(b - a)))
        mid = 0.5 * (a[j] + b[j])
        t = rec.stamp_s[first:end]
        tc, ta = crossing(t, rec.q_cmd[first:end, j], mid), crossing(t, rec.q_act[first:end, j], mid)
        if tc is not None and ta is not None:
            out.append((ta - tc) * 1e3)
    return out


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def row(label: str, values: np.ndarray | list[float], unit: str, digits: int = 1) -> None:
    print(f"    {label:<44}{figures(values, unit, digits)}")


def report(run: Run, base_us: np.ndarray | None, halves: tuple[np.ndarray, np.ndarray] | None) -> int:
    rec, s0, s1 = run.rec, run.s0, run.s1
    if run.ended and rec.n < 2:
        print(f"  INVALID: the task ended {run.ended} after {rec.n} ticks: {run.fault}")
        print(indent(f"the simulator logged:\n{run.sim_log or '(nothing)'}", "    "))
        return 1

    def delta(key: str) -> int:
        return int(s1[key]) - int(s0[key])

    period = 1.0 / float(s1["rate_hz"])
    period_us = period * 1e6
    rel = rec.release_ns.astype(np.float64)
    d_rel_us = np.diff(rel) * 1e-3
    d_stamp_ms = np.diff(rec.stamp_s) * 1e3
    unseen_in_record = int(np.maximum(np.round(np.diff(rec.stamp_s) / period) - 1, 0).sum())
    print(f"  our loop: {run.rt}")
    print(
        f"  {run.ticks} ticks measured ({delta('cycles')} controller cycles meanwhile), {run.overruns} "
        f"overruns, {run.missed_periods} periods skipped"
    )
    print("  timing:")
    row("tick release period (ours)", d_rel_us, "µs")
    row(f"  its jitter |period - {period_us:.0f} µs|", np.abs(d_rel_us - period_us), "µs")
    row("controller timestamp step", d_stamp_ms, "ms", 3)
    row(f"  its jitter |step - {period * 1e3:g} ms|", np.abs(d_stamp_ms - period * 1e3), "ms", 3)
    wake_us = None
    late = -1  # servoJ sent after the next cycle's scheduled start (-1: not known)
    origin = s1["clock_origin_s"]
    if origin is not None:
        cycle_ns = (rec.stamp_s + float(origin)) * 1e9  # each package's cycle: its scheduled start
        wake_us = rec.wake_ns * 1e-3
        row("wake-up, package read (blocking) -> release", wake_us, "µs")
        row("package age at release (since its cycle)", (rel - cycle_ns) * 1e-3, "µs")
        row("tick compute (release -> servoJ sent)", (rec.sent_ns - rel) * 1e-3, "µs")
        row("servoJ sent, since the package's cycle", (rec.sent_ns - cycle_ns) * 1e-3, "µs")
        late = int((rec.sent_ns - cycle_ns > period * 1e9).sum())
    else:
        print("    (the simulator gave no clock origin: wake-up latency and package age not measured)")
        row("tick compute (release -> servoJ sent)", (rec.sent_ns - rel) * 1e-3, "µs")
    sim_missed, skipped = delta("missed_periods"), delta("rtde_packages_skipped")
    rest = max(0, run.packets_missed - sim_missed - skipped)
    print(
        f"  controller cycles we did not see: {run.packets_missed} (backend packets_missed; "
        f"{unseen_in_record} in the timestamps recorded)"
    )
    print(
        f"    the simulator skipped the cycle {sim_missed}, its sender replaced the package unsent "
        f"{skipped}, the rest (ur_rtde's thread, our loop) {rest}"
    )
    stale, overwritten = delta("servoj_stale_cycles"), delta("servoj_overwritten")
    print(
        f"  servoJ updates the controller missed: {stale} of {delta('servoj_cycles')} servoj cycles "
        f"had no new command; {overwritten} commands were written over unread"
    )
    if late >= 0:
        print(f"    of our commands, {late} were sent after the next cycle's scheduled start")
    print(f"  command-to-motion latency (servoJ lookahead_time {run.lookahead_s:g} s, gain {run.gain:g}):")
    lags = lag_fit(rec.stamp_s, rec.q_cmd, rec.q_act, period)
    if lags:
        per_joint = ", ".join(f"j{j} {v * 1e3:.1f}" for j, v in lags.items())
        print(f"    best-fit shift, actual vs commanded: {per_joint} ms")
    row("per move: actual - commanded at mid-move", move_delays(rec), "ms")
    base = None
    if base_us is not None and halves is not None:
        base = float(np.percentile(base_us, 99))
        print(f"  cyclictest, {period_us:.0f} µs at the same priority, the simulator running (no client):")
        row("wake-up latency", base_us, "µs")
        p99s = [float(np.percentile(h, 99)) for h in halves]
        print(f"    p99 of the half before our loop {p99s[0]:.0f} µs, of the half after {p99s[1]:.0f} µs")
    if run.ended:
        print(f"  INVALID: the task ended {run.ended} after {rec.n} ticks: {run.fault}")
        print(f"    events: {', '.join(run.events) or 'none'}")
        print(indent(f"the simulator logged:\n{run.sim_log or '(nothing)'}", "    "))
        return 1
    print(
        f"  {verdict(run.packets_missed == 0 and stale == 0)}: no missed controller cycles "
        f"({run.packets_missed} unseen, {stale} without a new servoJ command)"
    )
    if wake_us is None or base is None:
        print("  (no wake-up figure or no cyclictest: the wake-up target is not judged)")
        return 0
    ours = float(np.percentile(wake_us, 99))
    print(
        f"  {verdict(ours <= base)}: wake-up p99 {ours:.0f} µs <= cyclictest p99 {base:.0f} µs: "
        f"ratio {ours / base:.2f}"
    )
    return 0


# ---- the run ----------------------------------------------------------------------------------
@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """SIGINT blocked while the simulator is started: it inherits the mask, so a Ctrl-C at the
    terminal reaches this process alone, which disconnects ur_rtde first and then stops it."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--priority", type=int, default=80, help="SCHED_FIFO of our loop and of cyclictest")
    ap.add_argument("--sim-priority", type=int, default=70, help="SCHED_FIFO of the simulator (0: normal)")
    ap.add_argument(
        "--sim-cpu", type=int, default=None, help="the simulator on this core only (default: any)"
    )
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the same clean-up as Ctrl-C
    print(
        f"ur_rtde_cycle: ur5e-rtde-sim by servoJ (ur_rtde backend, ur_rtde {version('ur_rtde')}) against "
        f"the UR simulator (SCHED_FIFO {args.sim_priority}), {args.duration_s:g} s"
    )
    sim_args = ["--boot", "running"] + (["--priority", str(args.sim_priority)] if args.sim_priority else [])
    sim_args += [] if args.sim_cpu is None else ["--cpu", str(args.sim_cpu)]
    with sigint_blocked():  # (waits while another simulator holds UR's ports)
        sim = UrSimProcess(CONFIG, *sim_args)
    try:
        period = 1.0 / float(sim.status()["rate_hz"])
        before = cyclictest(period, args.duration_s / 2, args.priority)
        run = run_ours(sim, args.duration_s, args.priority)
        run.sim_log = "\n".join(line for line in sim.log_text().splitlines() if " INFO " not in line)
        after = cyclictest(period, args.duration_s / 2, args.priority)
    finally:
        sim.stop()
    halves = None if before is None or after is None else (before, after)
    base = None if halves is None else np.concatenate(halves)
    return report(run, base, halves)


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except KeyboardInterrupt:  # the clean-up has run (ur_rtde disconnected, the simulator stopped)
        print("ur_rtde_cycle: interrupted", file=sys.stderr)
        raise SystemExit(130) from None
