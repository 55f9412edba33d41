"""Several resources in one daemon: each clock domain's timing, law switches and cross-resource
reactions, against cyclictest in the same run.

Runs orccadd (as a separate process, with its command daemon) on:

- **dual**: configs/robots/dual-arm-sim.toml (two simulated UR5e, `left` at 1 kHz and `right` at
  500 Hz, each plant in its own process), first holding (no switches), then with
  benchmarks/missions/station_switching.mission: each arm alternates a tracking law and a dwell,
  each par's end starting a law on both arms;
- **gripper**: configs/robots/ur5e-gripper-sim.toml (the UR controller simulator at 500 Hz, the
  arm device-paced, and the servo simulator's gripper at 200 Hz), holding, then pick_place.mission
  run again and again;
- **scale**: stations of 1, 2 and 4 simulated UR5e at 500 Hz, holding: how the figures grow;
- **isolation**: dual's station, `left` holding while `right` holds, then while `right` alone
  alternates the two laws (a mission on `right` only): each domain's figure while the other
  switches, in one daemon (`--units`: threads or processes);
- **separate**: dual's two arms each in a daemon of its own (two processes, two interpreters),
  `left` holding while `right` holds, then while `right` alternates the same two laws: the
  isolation a process per clock domain can reach on this machine, beside dual's one process.

Every tick of every resource is read here from the daemon's own telemetry rings (shared memory,
polled faster than they wrap), the automaton's instants from its trace ring. Printed per
resource: wake-up latency and compute time (median, p99, max), overruns; per law switch on the
resource whose event caused it, the ticks from the event's tick to the first tick of the new law
(0: in the tick of the event); per cross-resource reaction (an event of resource A starting a law
on B), the time from A's event tick to B's first tick of the new law, in B's periods; the ratio of
each resource's wake-up p99 to cyclictest's (1 kHz, the control threads' priority, half of its
run before ours and half after).

Usage: `python benchmarks/station.py [--duration-s 60] [--runs dual,gripper,scale,isolation,separate]
[--units auto|threads|processes]` (root, for
SCHED_FIFO; `make bench`).
"""

from __future__ import annotations

import argparse
import contextlib
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from harness import ROOT, cyclictest, figures, running_daemon

from orccadd.ctl.client import Client
from orccadd.dxlsim.process import DxlSimProcess
from orccadd.ursim.process import UrSimProcess
from orccadd.wire.schema import TRACE_IDX, H, R, T, Trace
from orccadd.wire.telemetry import RingReader, TelemetryBlock
from tests.daemon.conftest import station_copy

ROBOTS = ROOT / "configs/robots"
DUAL = ROBOTS / "dual-arm-sim.toml"
GRIPPER = ROBOTS / "ur5e-gripper-sim.toml"
UR5E = ROBOTS / "sim-ur5e.toml"
SWITCHING = ROOT / "benchmarks/missions/station_switching.mission"
PICK_PLACE = ROOT / "configs/missions/pick_place.mission"
POLL_S = 0.5  # the rings hold 16 s of ticks


@dataclass
class Recording:
    """Every tick of each resource and every instant, read from the daemon's telemetry."""

    names: list[str]
    periods_s: list[float]
    ticks: list[list[np.ndarray]] = field(default_factory=list)  # per resource: chunks of records
    trace: list[np.ndarray] = field(default_factory=list)
    lost: int = 0

    def resource_ticks(self, i: int) -> np.ndarray:
        return np.concatenate(self.ticks[i]) if self.ticks[i] else np.empty((0, len(T)))

    def instants(self) -> np.ndarray:
        rec = np.concatenate(self.trace) if self.trace else np.empty((0, len(R)))
        return rec[rec[:, R.KIND] == Trace.INSTANT] if len(rec) else rec


@contextlib.contextmanager
def recording(c: Client) -> Iterator[tuple[Recording, Callable[[], None]]]:
    """Attach to every resource's block; `poll()` reads what is new (call it every `POLL_S`)."""
    desc = c.call("describe")
    units = desc["resources"]
    blocks = [TelemetryBlock.attach(u["telemetry"]) for u in units]
    rec = Recording([u["name"] for u in units], [float(u["period_s"]) for u in units])
    rec.ticks = [[] for _ in units]
    readers = [RingReader(b.ticks, b.header, H.TICK_HEAD) for b in blocks]
    daemon = TelemetryBlock.attach(desc["daemon_telemetry"])  # the status and the trace
    trace = RingReader(daemon.trace, daemon.header, H.TRACE_HEAD)

    def poll() -> None:
        for i, r in enumerate(readers):
            rec.ticks[i].append(r.poll()[:, : len(T)])
        rec.trace.append(trace.poll())
        rec.lost = sum(r.lost for r in readers)

    try:
        yield rec, poll
    finally:
        poll()
        for b in blocks:
            b.close()


def run_for(duration_s: float, poll: Callable[[], None], each: Callable[[], None] = lambda: None) -> None:
    end = time.monotonic() + duration_s
    while time.monotonic() < end:
        time.sleep(POLL_S)
        poll()
        each()


def timing_lines(rec: Recording, label: str, base_p99: float | None) -> list[str]:
    out = []
    for i, name in enumerate(rec.names):
        t = rec.resource_ticks(i)
        if not len(t):
            out.append(f"  {label} {name}: no ticks")
            continue
        wake, comp = t[:, T.WAKE_US], t[:, T.COMPUTE_US]
        period_us = rec.periods_s[i] * 1e6
        overruns = int(((wake + comp) > period_us).sum())
        ratio = f"  p99/cyclictest {np.percentile(wake, 99) / base_p99:.2f}" if base_p99 else ""
        out.append(f"  {label} {name} ({period_us / 1e3:g} ms): wake-up {figures(wake, 'µs')}{ratio}")
        out.append(f"  {label} {name}: compute {figures(comp, 'µs')}; ticks over their period {overruns}")
    return out


def switch_figures(rec: Recording, desc: dict[str, Any]) -> tuple[list[float], list[float], list[float]]:
    """(law switches on the event's own resource, in ticks from the event's tick; cross-resource
    reactions in periods of the resource B whose law changed: from the event tick's release to
    B's first tick of the new law's release, and from the event tick's end (the event known) to
    that tick's end (B's new command sent))."""
    mission = desc["mission"]
    inputs, actions = mission["inputs"], mission["actions"]
    on = dict(zip(mission["tasks"], mission["task_resources"], strict=True))
    ids = {name: i for i, name in enumerate(desc["tasks"])}
    ticks = [rec.resource_ticks(i) for i in range(len(rec.names))]
    own, cross, sent = [], [], []
    for ins in rec.instants():
        n_in, n_act = int(ins[R.N_IN]), int(ins[R.N_ACT])
        names_in = [inputs[int(k)] for k in ins[len(R) : len(R) + n_in]]
        sources = {on.get(n.split(".")[0]) for n in names_in} - {None}
        if len(sources) != 1:
            continue  # an operator's input, or events of two resources in one instant
        (source,) = sources
        t_event = float(ins[R.T_S])
        acts = [actions[int(k)] for k in ins[len(R) + TRACE_IDX : len(R) + TRACE_IDX + n_act]]
        for act in acts:
            if not act.startswith("start "):
                continue
            task = act.removeprefix("start ")
            k = rec.names.index(on[task])
            t = ticks[k]
            after = np.nonzero((t[:, T.T_S] >= t_event - 1e-9) & (t[:, T.TASK] == ids[task]))[0]
            if not len(after):
                continue
            j = int(after[0])
            if on[task] == source:
                at = np.nonzero(np.abs(t[:, T.T_S] - t_event) < 1e-9)[0]
                if len(at):
                    own.append(float(j - int(at[0])))
            else:
                cross.append((float(t[j, T.T_S]) - t_event) / rec.periods_s[k])
                a = ticks[rec.names.index(source)]
                at = np.nonzero(np.abs(a[:, T.T_S] - t_event) < 1e-9)[0]
                if len(at):
                    i = int(at[0])
                    known = t_event + (a[i, T.WAKE_US] + a[i, T.COMPUTE_US]) * 1e-6
                    done = float(t[j, T.T_S]) + (t[j, T.WAKE_US] + t[j, T.COMPUTE_US]) * 1e-6
                    sent.append((done - known) / rec.periods_s[k])
    return own, cross, sent


def hold_then_run(
    c: Client,
    duration_s: float,
    base_p99: float | None,
    mission: Path,
    label: str,
    each: Callable[[], None] = lambda: None,
) -> list[str]:
    """Every resource holding for `duration_s`, then `mission` started and run for as long (then
    stopped if it still runs): the timing of both phases and the mission's switches."""
    with recording(c) as (rec, poll):
        run_for(duration_s, poll)
    out = timing_lines(rec, "holding  ", base_p99)
    c.call("load", path=str(mission))
    desc = c.call("describe")
    with recording(c) as (rec, poll):
        c.call("start")
        run_for(duration_s, poll, each)
        if c.call("status")["state"] == "running":
            c.call("stop")
    return out + timing_lines(rec, label, base_p99) + _switch_lines(rec, desc)


UNITS = "auto"  # `--units`: where each resource's control loop runs ([daemon] units)


def run_dual(duration_s: float, base_p99: float | None) -> list[str]:
    out = [f"dual-arm-sim (left 1 kHz, right 500 Hz; simulated arms in their own processes; units = {UNITS})"]
    with tempfile.TemporaryDirectory(prefix="orccadd-station-") as tmp:
        missions = f'mission_dirs = ["{ROOT}/configs/missions", "{ROOT}/benchmarks/missions"]'
        lines = f'{missions}\ntask_dirs = ["{ROOT}/configs/tasks"]\nunits = "{UNITS}"'
        cfg = station_copy(DUAL, Path(tmp), lines)
        t0 = time.monotonic()
        with running_daemon(cfg) as d, Client(d.socket, timeout_s=120) as c:
            up_s = time.monotonic() - t0
            out.append(
                f"  cost: {cost_line(d.proc.pid, c.call('describe'))}; up and answering in {up_s:.2f} s"
            )
            out += hold_then_run(c, duration_s, base_p99, SWITCHING, "switching")
    return out


def rss_mb(pid: int) -> float:
    """A process's resident memory (MB), 0 if it is gone."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    return next((int(line.split()[1]) / 1024 for line in text.splitlines() if line.startswith("VmRSS:")), 0.0)


def cost_line(daemon_pid: int, desc: dict[str, Any]) -> str:
    """The resident memory of the real-time process and of each resource's unit process (its
    own, or the real-time process's: counted once) — plants and the command daemon apart."""
    units = {int(u["unit_pid"]) for u in desc["resources"]} - {daemon_pid}
    each = ", ".join(f"{rss_mb(p):.0f}" for p in sorted(units))
    own = f" + unit processes {each} MB" if units else ""
    total = rss_mb(daemon_pid) + sum(rss_mb(p) for p in units)
    return f"resident memory: real-time process {rss_mb(daemon_pid):.0f} MB{own} = {total:.0f} MB"


def run_gripper(duration_s: float, base_p99: float | None) -> list[str]:
    out = ["ur5e-gripper-sim (the arm paced by the UR simulator's 500 Hz, the gripper at 200 Hz)"]
    with (
        UrSimProcess(GRIPPER, "--boot", "running", "--priority", "70"),
        DxlSimProcess(GRIPPER, "--priority", "70") as grip,
    ):
        grip.inject("object", device=1, at_rad=0.9, stiffness_nm_rad=20.0)
        with running_daemon(GRIPPER) as d, Client(d.socket, timeout_s=120) as c:
            runs = [1]

            def again() -> None:  # pick and place again, each time it ends
                s = c.call("status")
                if s["state"] == "ready":
                    if s["result"] != "success":
                        raise SystemExit(f"pick_place ended {s['result']}: {s.get('fault')}")
                    c.call("start")
                    runs[0] += 1

            out += hold_then_run(c, duration_s, base_p99, PICK_PLACE, "picking  ", again)
            out.append(f"  pick and place runs: {runs[0]}")
    return out


def run_scale(duration_s: float, base_p99: float | None, sizes: tuple[int, ...] = (1, 2, 4)) -> list[str]:
    out = ["stations of N simulated UR5e at 500 Hz, holding: the worst resource's figures"]
    for n in sizes:
        with tempfile.TemporaryDirectory(prefix="orccadd-station-") as tmp:
            cfg = Path(tmp) / f"arms{n}.toml"
            cfg.write_text(
                f'name = "arms{n}"\n'
                + "".join(f'[[resources]]\nname = "arm{i}"\nconfig = "{UR5E}"\n' for i in range(n))
                + f'[daemon]\ntask_dirs = ["{ROOT}/configs/tasks"]\n'
            )
            with running_daemon(cfg) as d, Client(d.socket, timeout_s=120) as c, recording(c) as (rec, poll):
                run_for(duration_s, poll)
        p99 = [np.percentile(rec.resource_ticks(i)[:, T.WAKE_US], 99) for i in range(n)]
        worst = int(np.argmax(p99))
        t = rec.resource_ticks(worst)
        over = sum(
            int(((x[:, T.WAKE_US] + x[:, T.COMPUTE_US]) > 2000.0).sum())
            for x in (rec.resource_ticks(i) for i in range(n))
        )
        ratio = f", p99/cyclictest {p99[worst] / base_p99:.2f}" if base_p99 else ""
        out.append(
            f"  {n} arm(s): wake-up {figures(t[:, T.WAKE_US], 'µs')}{ratio}; ticks over their period {over}"
        )
        out.append(f"  {n} arm(s): compute {figures(t[:, T.COMPUTE_US], 'µs')}")
    return out


SEPARATE_MISSION = """\
mission RightSwitch
resource right
input Stop
task TrackR on right from "{tasks}/move_joints.toml"
  set traj.target_rad = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
  set reached.ticks = 3
  post
end
task DwellR on right from "{tasks}/dwell.toml"
  set elapsed.timeout_s = 0.013
  post
end
main procedure Interleave
  do
    loop
      TrackR;
      DwellR
    end loop
  until Stop
on fatal do
  safe
end
safe procedure Acknowledge
  await Stop
end
"""


def run_separate(duration_s: float, base_p99: float | None) -> list[str]:
    """dual's arms in two daemons: left (1 kHz) holds throughout; right (500 Hz) holds, then
    alternates dual's tracking law and dwell (its own events only: two daemons share no mission)."""
    out = ["dual's arms in two daemons (left 1 kHz holding; right 500 Hz holding, then switching)"]
    with tempfile.TemporaryDirectory(prefix="orccadd-station-") as tmp:
        configs = []
        arms = (("left", 0.001, "loop = { overrun_limit = 50 }\n"), ("right", 0.002, ""))
        for name, period_s, extra in arms:
            cfg = Path(tmp) / f"{name}.toml"
            cfg.write_text(
                f'name = "{name}"\n[[resources]]\nname = "{name}"\nconfig = "{UR5E}"\n'
                f"control_period_s = {period_s}\n{extra}"
                f'[daemon]\ntask_dirs = ["{ROOT}/configs/tasks"]\nmission_dirs = ["{tmp}"]\n'
            )
            configs.append(cfg)
        mission = Path(tmp) / "right_switch.mission"
        mission.write_text(SEPARATE_MISSION.format(tasks=ROOT / "configs/tasks"))
        with (
            running_daemon(configs[0]) as dl,
            running_daemon(configs[1]) as dr,
            Client(dl.socket, timeout_s=120) as left,
            Client(dr.socket, timeout_s=120) as right,
        ):
            with recording(left) as (rec, poll):
                run_for(duration_s, poll)
            out += timing_lines(rec, "right holding  ", base_p99)
            right.call("load", path=str(mission))
            with recording(left) as (rec, poll), recording(right) as (rec_r, poll_r):
                right.call("start")
                run_for(duration_s, lambda: (poll(), poll_r()))
                right.call("stop")
            out += timing_lines(rec, "right switching", base_p99)
            switches = rec_r.resource_ticks(0)[:, T.TASK]
            out.append(f"  right's law switches meanwhile: {int((switches[1:] != switches[:-1]).sum())}")
    return out


def run_isolation(duration_s: float, base_p99: float | None) -> list[str]:
    """dual's station: left holds throughout; right holds, then alternates its two laws."""
    out = [f"dual-arm-sim, left holding; right holding, then switching (units = {UNITS})"]
    with tempfile.TemporaryDirectory(prefix="orccadd-station-") as tmp:
        lines = f'mission_dirs = ["{tmp}"]\ntask_dirs = ["{ROOT}/configs/tasks"]\nunits = "{UNITS}"'
        cfg = station_copy(DUAL, Path(tmp), lines)
        mission = Path(tmp) / "right_switch.mission"
        mission.write_text(SEPARATE_MISSION.format(tasks=ROOT / "configs/tasks"))
        with running_daemon(cfg) as d, Client(d.socket, timeout_s=120) as c:
            with recording(c) as (rec, poll):
                run_for(duration_s, poll)
            out += timing_lines(rec, "right holding  ", base_p99)
            c.call("load", path=str(mission))
            with recording(c) as (rec, poll):
                c.call("start")
                run_for(duration_s, poll)
                c.call("stop")
            out += timing_lines(rec, "right switching", base_p99)
            tasks = rec.resource_ticks(1)[:, T.TASK]
            out.append(f"  right's law switches meanwhile: {int((tasks[1:] != tasks[:-1]).sum())}")
            out.append(f"  stalls longer than a period shared by both domains: {shared_stalls(rec)}")
    return out


def shared_stalls(rec: Recording) -> str:
    """The ticks of each domain released later than its period, overlapping in time with such a
    tick of the other domain: their count and the longest (a stall both saw)."""
    late = []
    for i in range(len(rec.names)):
        t = rec.resource_ticks(i)
        period_us = rec.periods_s[i] * 1e6
        mask = t[:, T.WAKE_US] > period_us
        late.append([(s, s + w * 1e-6) for s, w in zip(t[mask, T.T_S], t[mask, T.WAKE_US], strict=True)])
    shared = [min(a1, b1) - max(a0, b0) for a0, a1 in late[0] for b0, b1 in late[1] if a0 < b1 and b0 < a1]
    return f"{len(shared)}, longest {max(shared) * 1e3:.2f} ms" if shared else "none"


def _switch_lines(rec: Recording, desc: dict[str, Any]) -> list[str]:
    own, cross, sent = switch_figures(rec, desc)
    in_tick = 100.0 * sum(1 for x in own if x == 0) / len(own) if own else float("nan")
    lines = [
        f"  law switches on the event's resource: {len(own)}, {in_tick:.1f} % in the tick of the event;"
        f" ticks after it: {figures(own, 'ticks', 0)}",
        "  cross-resource reactions (event on A → first tick of B's new law): "
        + figures(cross, "periods of B", 2),
        "  the same from A's tick end (the event known) to that tick's end (B's command sent): "
        + figures(sent, "periods of B", 2),
    ]
    if rec.lost:
        lines.append(f"  (records lost: {rec.lost}: the figures miss them)")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration-s", type=float, default=60.0, help="each phase of each run")
    ap.add_argument(
        "--runs", default="dual,gripper,scale", help="which: dual, gripper, scale, isolation, separate"
    )
    ap.add_argument("--priority", type=int, default=80, help="cyclictest's: the control threads'")
    ap.add_argument(
        "--units", choices=("auto", "threads", "processes"), default="auto", help="dual: [daemon] units"
    )
    args = ap.parse_args()
    global UNITS
    UNITS = args.units
    runs = [r.strip() for r in args.runs.split(",") if r.strip()]
    table = {
        "dual": run_dual,
        "gripper": run_gripper,
        "scale": run_scale,
        "isolation": run_isolation,
        "separate": run_separate,
    }
    unknown = [r for r in runs if r not in table]
    if unknown:
        ap.error(f"--runs: unknown {', '.join(unknown)} (known: {', '.join(table)})")
    before = cyclictest(0.001, args.duration_s / 2, args.priority)
    base_p99 = None if before is None else float(np.percentile(before, 99))
    lines: list[str] = []
    for name in runs:
        lines += table[name](args.duration_s, base_p99)
    after = cyclictest(0.001, args.duration_s / 2, args.priority)
    if before is not None and after is not None:
        print(f"cyclictest 1 kHz, SCHED_FIFO {args.priority}, before: {figures(before, 'µs')}")
        print(f"cyclictest 1 kHz, SCHED_FIFO {args.priority}, after:  {figures(after, 'µs')}")
        print(f"(the ratios below: to the p99 before, {base_p99:.1f} µs)")
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
