"""Soak test (issue 15): missions in a loop at 500 Hz for hours, under client load and faults.

Runs `orccadd --allow-fault-injection` (sim-ur5e: 500 Hz, the plant in its own process) and,
all through the real socket:

- the operator: `start` the mission (configs/missions/demo.mission: three motions and a type 2
  recovery, ~4 s), follow `status` to its end, again; `load` again every `--reload-every` runs
  (a compile worker process each time);
- faults in the middle of a run: `inject fault=resource` every `--fault-every-s`, then what an
  operator does: `stop` (the safe procedure awaits Stop), wait for the arm at rest, `reset`, go
  on; `inject fault=overrun` every `--overrun-every-s`, alternately shorter than
  `daemon.overrun_limit` (the mission must carry on) and longer (type 3 Overrun, recovered as
  above);
- `--monitors` `orccadctl monitor --rate 100` processes, each killed (SIGKILL: no goodbye) and
  restarted every `--monitor-life-s`, staggered; every `--stall-every-s` a client that asks for a
  500 Hz monitor and never reads (the command daemon must drop it and free its slot);
- a client tuning `<active task>.traj.speed_scale` at 10 Hz;
- hostile clients (`soak_hostile`), every `--hostile-every-s`: in the middle of a run, every
  place of the urgent and main sockets held (slow senders, idle connections) while
  `orccadctl abort` must still abort; between them, a log of 12,000 signals with `status` timed
  all through, in a log directory of `--small-log-dir-kb` (a tmpfs, root) that it fills: the log
  ends saying so and leaves every file readable.

Measured: every tick record of the shared-memory ring. A tick overran when the next release
came more than one period after its own (our clocks release on the nominal deadline, so the
gap is the periods skipped); ticks within `inject fault=overrun` windows are counted apart.
Every `--sample-s`: RSS and open fds of every process under orccadd (real-time process, command
daemon, plant, resource tracker, compile worker when alive) and the command daemon's client
connections (its sockets accepted on the public path, from /proc/net/unix: `status` does not
report its slots).

Prints a progress line every `--progress-s`, then the report. Exit status 1 if a process died or
was restarted or outlived the teardown; fds or connections grew steadily (after the warm-up, the
lowest value of the last third of the samples above the highest of the first third); the command
daemon still held a client that had stopped reading `STALL_HOLD_S` before, or any connection once
every client had closed; a load, a run or a recovery failed. Ctrl-C (or SIGTERM) ends the soak
early with its report; everything it started is stopped.

Usage: `python benchmarks/soak.py --hours 8` or `--minutes 30` (root for SCHED_FIFO).
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import os
import random
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from harness import ROOT, running_daemon
from soak_hostile import (
    STATUS_LIMIT_S,
    SmallLogDir,
    abort_through_holders,
    empty,
    huge_log,
    unreadable_log_files,
)

from orccadd.config.robot import read_robot_config
from orccadd.ctl.client import Client, ClientError
from orccadd.wire.commands import encode
from orccadd.wire.schema import TICK_FIELDS, TICK_VECTORS, H, T
from orccadd.wire.telemetry import RingReader, TelemetryBlock

PERIOD_S = 0.002  # 500 Hz
MISSION = ROOT / "configs/missions/demo.mission"
TUNE_PARAM = "traj.speed_scale"
TUNE_HZ = 10.0
MONITOR_HZ = 100.0
RUN_TIMEOUT_S = 60.0  # a demo run takes ~4 s
RECOVERY_TIMEOUT_S = 30.0
INJECTED_MARGIN_S = 0.5  # ticks counted as injected after the injected ones
CAUSE_S = 1.0  # an overrun this soon after an operator action is attributed to it
STALL_GRACE_S = 20.0  # the daemon drops a client that stops reading after 10 s (cmdd STALL_S)
STALL_HOLD_S = 25.0  # a stalled client then checks it was dropped, and closes
TICK_RING_S = 16.0  # what the telemetry ring keeps (orccadd.daemon.rtproc)


# ---- counters shared by the workers ------------------------------------------------------------
class Tally:
    """Thread-safe counters and a few first messages of each kind of problem."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.n: collections.Counter[str] = collections.Counter()
        self.notes: dict[str, list[str]] = collections.defaultdict(list)
        self.times: dict[str, list[float]] = collections.defaultdict(list)

    def add(self, key: str, k: int = 1) -> None:
        with self.lock:
            self.n[key] += k

    def note(self, key: str, msg: str) -> None:
        with self.lock:
            self.n[key] += 1
            if len(self.notes[key]) < 5:
                self.notes[key].append(f"{time.strftime('%H:%M:%S')} {msg[:300]}")

    def time(self, key: str, value: float) -> None:
        with self.lock:
            self.times[key].append(value)


class CountingClient(Client):
    """A `Client` that counts the requests it sends."""

    def __init__(self, path: str, tally: Tally, timeout_s: float = 10.0) -> None:
        super().__init__(path, timeout_s)
        self.tally = tally
        tally.add("open")

    def _send(self, cmd: str, args: dict[str, Any]) -> int:
        self.tally.add("requests")
        return super()._send(cmd, args)

    def close(self) -> None:
        super().close()
        self.tally.add("open", -1)


class Worker(threading.Thread):
    """A soak thread: an unexpected exception ends the soak (kept in `fatal`, not lost on stderr)."""

    def __init__(self, name: str, stop: threading.Event, fatal: list[str]) -> None:
        super().__init__(name=name, daemon=True)
        self.stop = stop
        self.fatal = fatal

    def run(self) -> None:
        try:
            self.work()
        except Exception as e:
            if not self.stop.is_set():
                self.fatal.append(f"{self.name}: {type(e).__name__}: {e}")
                self.stop.set()

    def work(self) -> None:
        raise NotImplementedError


# ---- deadlines, from the tick ring ---------------------------------------------------------------
class Histogram:
    """Counts of values in µs: 0.1 µs bins below 1 ms, 10 µs bins to 1 s, then one bin; the max."""

    FINE_N, FINE_US, COARSE_N, COARSE_US = 10_000, 0.1, 100_000, 10.0

    def __init__(self) -> None:
        self.counts = np.zeros(self.FINE_N + self.COARSE_N + 1, dtype=np.int64)
        fine = np.arange(1, self.FINE_N + 1) * self.FINE_US
        coarse = 1000.0 + np.arange(1, self.COARSE_N + 1) * self.COARSE_US
        self.upper = np.concatenate([fine, coarse, [np.inf]])  # each bin's upper edge
        self.max = 0.0

    def add(self, v: np.ndarray) -> None:
        if v.size == 0:
            return
        v = np.maximum(v, 0.0)
        fine_end = self.FINE_N * self.FINE_US
        idx = np.where(v < fine_end, v / self.FINE_US, self.FINE_N + (v - fine_end) / self.COARSE_US)
        np.add.at(self.counts, np.minimum(idx.astype(np.int64), len(self.counts) - 1), 1)
        self.max = max(self.max, float(v.max()))

    def figures(self, unit: str = "µs") -> str:
        n = int(self.counts.sum())
        if not n:
            return "no samples"
        cum = np.cumsum(self.counts)
        med, p99, p999 = (
            min(float(self.upper[np.searchsorted(cum, q * n)]), self.max) for q in (0.5, 0.99, 0.999)
        )
        return f"median {med:.1f}  p99 {p99:.1f}  p99.9 {p999:.1f}  max {self.max:.1f} {unit}  (n={n})"


@dataclass
class Deadlines:
    ticks: int = 0  # judged (the last one waits for its successor)
    unjudged: int = 0  # torn or lost records: no verdict
    overruns: int = 0  # spontaneous
    skipped: int = 0  # periods skipped by them
    runs: collections.Counter[int] = field(default_factory=collections.Counter)
    causes: collections.Counter[str] = field(default_factory=collections.Counter)  # runs by cause
    injected_ticks: int = 0
    injected_overruns: int = 0
    injected_runs: collections.Counter[int] = field(default_factory=collections.Counter)


class TickMeter(Worker):
    """Follows the tick ring; judges every tick; keeps latency histograms of the spontaneous ones."""

    def __init__(self, tel: TelemetryBlock, stop: threading.Event, fatal: list[str]) -> None:
        super().__init__("ticks", stop, fatal)
        self.tel = tel
        self.lock = threading.Lock()
        self.reader = RingReader(tel.ticks, tel.header, H.TICK_HEAD, from_now=True)
        self.d = Deadlines()
        self.wake = Histogram()
        self.compute = Histogram()
        self.windows: list[list[int]] = []  # [first, last] tick seq of an injected overrun
        self.marks: collections.deque[tuple[int, str]] = collections.deque()
        self.prev: np.ndarray | None = None
        self.run_len = self.run_first = self.run_last = 0
        self.run_injected = False
        self.overruns = [int(tel.header[H.OVERRUNS]), 0]  # the loop's own count, first and last poll

    def head(self) -> int:
        return int(self.tel.header[H.TICK_HEAD])

    def mark(self, label: str) -> None:
        """An operator action now: overrun runs starting within `CAUSE_S` are attributed to it."""
        with self.lock:
            self.marks.append((self.head(), label))

    def open_window(self) -> list[int]:
        """Before `inject fault=overrun`: the ticks from now on are injected ones…"""
        w = [self.head(), 2**62]
        with self.lock:
            self.windows.append(w)
        return w

    def close_window(self, w: list[int], ticks: int) -> None:
        """…until `ticks` (+ a margin) after the reply."""
        with self.lock:
            w[1] = self.head() + ticks + int(INJECTED_MARGIN_S / self.tel.period_s)

    def work(self) -> None:
        while not self.stop.wait(0.25):
            self.poll()

    def poll(self) -> None:
        new = self.reader.poll()
        if not len(new):
            return
        recs = new if self.prev is None else np.vstack([self.prev, new])
        self.prev = recs[-1].copy()
        with self.lock:
            self._judge(recs)

    def _judge(self, r: np.ndarray) -> None:
        """Each record but the last, judged by the next one's release time."""
        seq = r[:, T.SEQ].astype(np.int64)
        ok = np.diff(seq) == 1
        gap = np.diff(r[:, T.T_S]) / self.tel.period_s
        over = ok & (gap > 1.5)
        s = seq[:-1]
        injected = np.zeros(len(s), dtype=bool)
        for lo, hi in self.windows:
            injected |= (s >= lo) & (s <= hi)
        d = self.d
        d.ticks += int(ok.sum())
        d.unjudged += int((~ok).sum())
        spont = ok & ~injected
        self.wake.add(r[:-1][spont, T.WAKE_US])
        self.compute.add(r[:-1][spont, T.COMPUTE_US])
        d.injected_ticks += int((ok & injected).sum())
        d.injected_overruns += int((over & injected).sum())
        d.overruns += int((over & ~injected).sum())
        d.skipped += int(np.rint(gap[over & ~injected] - 1).sum())
        for k in np.flatnonzero(over):
            self._extend_run(int(s[k]), bool(injected[k]))
        if self.run_len and self.run_last < s[-1]:  # the run ended inside this chunk
            self._flush_run()
        oldest = int(s[0]) - int(CAUSE_S / self.tel.period_s)
        while self.marks and self.marks[0][0] < oldest - 10_000:
            self.marks.popleft()
        self.windows = [w for w in self.windows if w[1] >= s[-1]]

    def _extend_run(self, s: int, injected: bool) -> None:
        if self.run_len and s == self.run_last + 1:
            self.run_len += 1
            self.run_injected |= injected
        else:
            self._flush_run()
            self.run_len, self.run_first, self.run_injected = 1, s, injected
        self.run_last = s

    def _flush_run(self) -> None:
        if not self.run_len:
            return
        if self.run_injected:
            self.d.injected_runs[self.run_len] += 1
        else:
            self.d.runs[self.run_len] += 1
            self.d.causes[self._cause(self.run_first)] += 1
        self.run_len = 0

    def _cause(self, s: int) -> str:
        window = int(CAUSE_S / self.tel.period_s)
        near = [label for m, label in self.marks if s - window <= m <= s]
        return near[-1] if near else "none"

    def finish(self) -> None:
        self.overruns[1] = int(self.tel.header[H.OVERRUNS])
        self.poll()
        with self.lock:
            self._flush_run()

    def progress(self) -> str:
        with self.lock:
            d = self.d
            longest = max(d.runs, default=0)
            return f"ticks {d.ticks}, overruns {d.overruns} (longest {longest})"


# ---- processes, from /proc -----------------------------------------------------------------------
ROLES = {
    "orccadd.cmdd": "cmdd",
    "orccadd.plantsim": "plant",
    "orccadd.daemon.compile_worker": "compile worker",
}
TRANSIENT = {"compile worker"}


@dataclass(frozen=True)
class Proc:
    pid: int
    rss_kb: int
    fds: int
    sockets: int


@dataclass
class Sample:
    t_s: float
    procs: dict[str, Proc]
    connections: int  # the command daemon's client connections
    ours: int  # connections this soak held (operator, tuner, monitor processes, young stalled clients)


def descendants(pid: int) -> Iterator[tuple[int, int]]:
    """(pid, parent pid) of every process under `pid`."""
    todo = [pid]
    while todo:
        p = todo.pop()
        for f in Path(f"/proc/{p}/task").glob("*/children"):
            try:
                kids = [int(x) for x in f.read_text().split()]
            except OSError:
                continue
            yield from ((k, p) for k in kids)
            todo += kids


def role_of(pid: int) -> str:
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return "?"
    if "-m" in argv[:-1]:
        module = argv[argv.index("-m") + 1]
        return ROLES.get(module, module)
    if any("resource_tracker" in a for a in argv):
        return "resource tracker"
    return Path(argv[0]).name


def fd_links(pid: int) -> list[str] | None:
    """Where the process's open fds lead (None if it is gone)."""
    links = []
    try:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            with contextlib.suppress(OSError):  # closed meanwhile
                links.append(os.readlink(f"/proc/{pid}/fd/{fd}"))
    except OSError:
        return None
    return links


def proc_stats(pid: int) -> Proc | None:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    links = fd_links(pid)
    if links is None:
        return None
    m = re.search(r"^VmRSS:\s+(\d+) kB", status, re.M)
    return Proc(pid, int(m.group(1)) if m else 0, len(links), sum(x.startswith("socket:") for x in links))


def client_connections(pid: int, path: str) -> int:
    """The process's connected Unix sockets bound to `path` (accepted on the public socket)."""
    links = fd_links(pid)
    try:
        lines = Path("/proc/net/unix").read_text().splitlines()[1:]
    except OSError:
        return -1
    if links is None:
        return -1
    inodes = {link[8:-1] for link in links if link.startswith("socket:[")}
    n = 0
    for line in lines:
        f = line.split()
        if len(f) >= 8 and f[7] == path and f[5] == "03" and f[6] in inodes:  # 03: connected
            n += 1
    return n


def sample(rt_pid: int, sock: str, t_s: float, ours: int) -> Sample:
    procs: dict[str, Proc] = {}
    roles = {rt_pid: "orccadd"}
    for pid, parent in [(rt_pid, 0), *descendants(rt_pid)]:
        role = roles.setdefault(pid, role_of(pid))
        if role == "resource tracker":  # multiprocessing's, one per process using shared memory
            role = roles[pid] = f"{roles.get(parent, '?')}'s resource tracker"
        st = proc_stats(pid)
        if st is not None:
            procs[role if role not in procs else f"{role} ({pid})"] = st
    cmdd = procs.get("cmdd")
    conns = client_connections(cmdd.pid, sock) if cmdd else -1
    return Sample(t_s, procs, conns, ours)


# ---- the workers ---------------------------------------------------------------------------------
class Operator(Worker):
    """Missions in a loop, and the faults, as one operator would do them (one connection)."""

    def __init__(self, soak: Soak) -> None:
        super().__init__("operator", soak.stop, soak.fatal)
        self.s = soak
        self.rng = random.Random(soak.args.seed)
        self.refused = 0  # starts refused in a row

    def work(self) -> None:
        with CountingClient(self.s.sock, self.s.tally, timeout_s=120) as c:
            self._loop(c)

    def _loop(self, c: Client) -> None:
        args, tally = self.s.args, self.s.tally
        runs = 0
        next_fault = self.s.t0 + args.fault_first_s
        next_overrun = self.s.t0 + args.overrun_first_s
        next_hostile = self.s.t0 + args.hostile_every_s if args.hostile_every_s else float("inf")
        overruns = 0
        while not self.s.stop.is_set():
            if runs % args.reload_every == 0:
                self.s.meter.mark("load")
                t = time.monotonic()
                r = c.reply("load", path=str(self.s.mission))
                if r.get("ok"):
                    tally.time("load_s", time.monotonic() - t)
                    tally.add("loads")
                else:
                    tally.note("load_failed", str(r.get("error")))
            now = time.monotonic()
            fault = ""
            if now >= next_fault:
                fault, next_fault = "resource", now + args.fault_every_s * self.rng.uniform(0.85, 1.15)
            elif now >= next_overrun:
                fault = "overrun" if overruns % 2 == 0 else "overrun-t3"
                overruns += 1
                next_overrun = now + args.overrun_every_s * self.rng.uniform(0.85, 1.15)
            elif now >= next_hostile:
                fault, next_hostile = "hostile-abort", now + args.hostile_every_s
            self._run_once(c, fault)
            runs += 1

    def _status(self, c: Client) -> dict[str, Any]:
        s: dict[str, Any] = c.call("status")
        return s

    def _run_once(self, c: Client, fault: str) -> None:
        tally, meter = self.s.tally, self.s.meter
        meter.mark("start")
        r = c.reply("start")
        t0 = time.monotonic()
        if not r.get("ok"):
            tally.note("run_failed", f"start refused: {r.get('error')}")
            self.refused += 1
            if self.refused >= 5:
                raise ClientError(f"start refused 5 times in a row: {r.get('error')}")
            self._recover(c, "", t0)
            return
        self.refused = 0
        inject_at = t0 + self.rng.uniform(0.5, 2.5) if fault else None
        s = self._status(c)
        while True:
            if inject_at is not None and time.monotonic() >= inject_at:
                self._inject(c, fault)
                inject_at = None
            s = self._status(c)
            if s["state"] not in ("running", "holding") or s["faulted"]:
                break
            if self.s.stop.is_set():
                return
            if time.monotonic() - t0 > RUN_TIMEOUT_S:
                tally.note("run_failed", f"run not over after {RUN_TIMEOUT_S:g} s: {_brief(s)}")
                c.reply("abort")
                self._recover(c, "", time.monotonic())
                return
            self.s.stop.wait(0.1)
        if inject_at is not None:  # the run ended first: the fault hits the Hold task
            self._inject(c, fault)
            s = self._wait(c, lambda s: bool(s["faulted"]), 0.5)
        t_inj = time.monotonic()
        if fault == "hostile-abort":
            s = self._wait(c, lambda s: bool(s["faulted"]) and s["state"] not in ("running", "holding"), 5.0)
            if s["result"] != "aborted":
                tally.note("abort_denied", f"the run did not end aborted: {_brief(s)}")
            self._recover(c, "aborted", t_inj)
            tally.add("runs_aborted")
            return
        if fault in ("resource", "overrun-t3"):
            s = self._wait(c, lambda s: bool(s["faulted"]), 5.0)
            if not s["faulted"]:
                tally.note("recovery_failed", f"{fault}: no safe stop followed: {_brief(s)}")
                return
            self._recover(c, "ResourceFault" if fault == "resource" else "Overrun", t_inj)
            s = self._status(c)
            if s["result"] == "safe":
                tally.add("runs_faulted")
            elif s["result"] == "success":  # it hit the Hold task, after the run
                tally.add("runs_ok")
            else:
                tally.note("run_failed", f"run ended {s['result']} after an injected {fault}: {_brief(s)}")
            return
        if fault == "overrun":
            tally.add(
                "overrun_broke_run" if s["faulted"] or s["result"] != "success" else "overrun_carried_on"
            )
        if s["faulted"]:
            dump = self.s.dump_ticks()
            tally.note(
                "run_failed",
                f"a safe stop nobody injected (injected: {fault or 'nothing'}): {_brief(s)}; the last "
                f"{TICK_RING_S:g} s of ticks: {dump}",
            )
            self._recover(c, "", t_inj)
        elif s["result"] == "success":
            tally.add("runs_ok")
        else:
            tally.note("run_failed", f"run ended {s['result']} (injected: {fault or 'nothing'}): {_brief(s)}")

    def _inject(self, c: Client, fault: str) -> None:
        meter, limit = self.s.meter, self.s.overrun_limit
        if fault == "resource":
            meter.mark("inject resource")
            c.call("inject", fault="resource")
        elif fault == "hostile-abort":
            meter.mark("hostile abort")
            free = self.s.control_clients - self.s.ours()
            code, err, took_s = abort_through_holders(self.s.sock, free, self.s.opened)
            self.s.tally.time("hostile_abort_s", took_s)
            if code != 0:
                self.s.tally.note("abort_denied", f"orccadctl abort exited {code}: {err}")
        else:
            ticks = max(1, limit - 5) if fault == "overrun" else limit + 10
            w = meter.open_window()
            c.call("inject", fault="overrun", ticks=ticks)
            meter.close_window(w, ticks)
        self.s.tally.add(f"injected {fault}")

    def _wait(self, c: Client, pred: Callable[[dict[str, Any]], bool], timeout_s: float) -> dict[str, Any]:
        end = time.monotonic() + timeout_s
        while True:
            s = self._status(c)
            if pred(s) or time.monotonic() > end or self.s.stop.is_set():
                return s
            time.sleep(0.05)

    def _recover(self, c: Client, expected: str, t_inj: float) -> None:
        """What an operator does after a safe stop: Stop (the safe procedure awaits it), wait
        for the arm at rest, `reset`."""
        tally, meter = self.s.tally, self.s.meter
        s = self._status(c)
        if expected and expected not in str(s["fault"]):
            tally.note("recovery_failed", f"expected a {expected} fault, got: {s['fault']}")
        end = time.monotonic() + RECOVERY_TIMEOUT_S
        if s["state"] in ("running", "holding"):
            meter.mark("stop")
            c.reply("stop")
            s = self._wait(c, lambda s: s["state"] not in ("running", "holding"), 5.0)
            if s["state"] in ("running", "holding"):
                tally.note("recovery_failed", f"Stop did not end the safe procedure: {_brief(s)}")
                c.reply("abort")
        s = self._wait(c, lambda s: "stopped" in s["resource_status"], RECOVERY_TIMEOUT_S)
        r: dict[str, Any] = {}
        while time.monotonic() < end and not self.s.stop.is_set():
            meter.mark("reset")
            r = c.reply("reset")
            if r.get("ok") and r["result"].get("reset"):
                break
            time.sleep(0.2)
        else:
            tally.note(
                "recovery_failed", f"reset refused for {RECOVERY_TIMEOUT_S:g} s: {r.get('error') or r}"
            )
            return
        s = self._status(c)
        if s["faulted"] or {"fault", "stopped", "stopping"} & set(s["resource_status"]):
            tally.note("recovery_failed", f"after reset: {_brief(s)}")
            return
        if expected:
            tally.add("recovered")
            tally.time("recovery_s", time.monotonic() - t_inj)


def _brief(s: dict[str, Any]) -> str:
    keys = ("state", "result", "faulted", "fault", "active_task", "resource_status")
    return ", ".join(f"{k}={s.get(k)}" for k in keys)


class Tuner(Worker):
    """`<active task>.traj.speed_scale` at 10 Hz, alternating between two values; a connection
    lost is noted (a problem) and made again."""

    def __init__(self, soak: Soak) -> None:
        super().__init__("tuner", soak.stop, soak.fatal)
        self.s = soak
        self.k = 0

    def work(self) -> None:
        while not self.stop.is_set():
            try:
                with CountingClient(self.s.sock, self.s.tally) as c:
                    self._tune(c)
                return
            except (ClientError, OSError) as e:
                if not self.stop.is_set():
                    self.s.tally.note("client_failed", f"tuner: {type(e).__name__}: {e}")
                    self.stop.wait(1.0)

    def _tune(self, c: Client) -> None:
        tally = self.s.tally
        end = time.monotonic() + 60.0
        while True:  # until the first load is done
            tasks: dict[str, list[dict[str, Any]]] = c.call("params")["params"]
            names = list(tasks)  # telemetry task ids: 0 the Hold task, k the mission's k-1
            with_param = [n for n, ps in tasks.items() if any(p["name"] == TUNE_PARAM for p in ps)]
            if with_param or time.monotonic() > end or self.stop.wait(0.5):
                break
        if not with_param:
            tally.note("tune_refused", f"no task of the mission has {TUNE_PARAM}: not tuning")
            return
        nxt = time.monotonic()
        while not self.stop.is_set():
            tid = int(self.s.latest_task())
            task = names[tid] if 0 <= tid < len(names) and names[tid] in with_param else with_param[0]
            r = c.reply("tune", path=f"{task}.{TUNE_PARAM}", value=0.6 if self.k % 2 else 0.8)
            if r.get("ok"):
                tally.add("tunes")
            else:
                tally.note("tune_refused", str(r.get("error")))
            self.k += 1
            nxt += 1.0 / TUNE_HZ
            self.stop.wait(max(0.0, nxt - time.monotonic()))


class Monitors(Worker):
    """`orccadctl monitor` processes killed (SIGKILL) and restarted, staggered; stalled clients."""

    def __init__(self, soak: Soak) -> None:
        super().__init__("monitors", soak.stop, soak.fatal)
        self.s = soak
        n, life = soak.args.monitors, soak.args.monitor_life_s
        self.procs: list[subprocess.Popen[bytes] | None] = [None] * n
        now = time.monotonic()
        self.kill_at = [now + life * (i + 1) / n for i in range(n)]
        self.errlog = (soak.tmp / "monitors.err").open("ab")
        self.stalled: dict[int, float] = {}  # stalled clients: thread id -> when it connected
        self.stall_threads: list[threading.Thread] = []

    def alive(self) -> int:
        """Monitor processes running, and stalled clients the daemon may still serve."""
        now = time.monotonic()
        young = sum(now - t < STALL_GRACE_S for t in list(self.stalled.values()))
        return sum(p is not None and p.poll() is None for p in self.procs) + young

    def _spawn(self, i: int) -> None:
        env = {**os.environ, "ORCCADD_SOCKET": self.s.sock}
        cmd = [
            sys.executable,
            "-m",
            "orccadd.cli",
            "monitor",
            "q",
            "dq",
            "--rate",
            f"{MONITOR_HZ:g}",
            "--json",
        ]
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.errlog, env=env, start_new_session=True)
        self.procs[i] = p
        self.s.tally.add("requests")
        threading.Thread(target=self._drain, args=(p,), daemon=True).start()

    def _drain(self, p: subprocess.Popen[bytes]) -> None:
        assert p.stdout is not None
        n = sum(1 for _ in p.stdout)
        self.s.tally.add("monitor_samples", n)

    def work(self) -> None:
        args, tally = self.s.args, self.s.tally
        for i in range(len(self.procs)):
            self._spawn(i)
        next_stall = time.monotonic() + args.stall_every_s / 2
        while not self.s.stop.wait(0.5):
            now = time.monotonic()
            for i, p in enumerate(self.procs):
                if p is not None and p.poll() is not None:
                    tally.note("monitor_ended", f"a monitor process ended by itself (code {p.returncode})")
                    self._spawn(i)
                elif p is not None and now >= self.kill_at[i]:
                    p.kill()
                    p.wait()
                    tally.add("monitor_kills")
                    self.s.meter.mark("monitor restart")
                    self._spawn(i)
                    self.kill_at[i] += args.monitor_life_s
            if args.stall_every_s and now >= next_stall:
                next_stall = now + args.stall_every_s
                t = threading.Thread(target=self._stall, daemon=True)
                t.start()
                self.stall_threads = [*(x for x in self.stall_threads if x.is_alive()), t]

    def _stall(self) -> None:
        """Ask for a fast monitor stream and never read it. After `STALL_HOLD_S` the daemon must
        have dropped it: its connections then exceed this soak's clients if it still holds it."""
        tally = self.s.tally
        try:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.connect(self.s.sock)
        except OSError as e:
            tally.note("client_failed", f"stalled client: {e}")
            return
        me = threading.get_ident()
        self.stalled[me] = time.monotonic()
        try:
            signals = ["q", "dq", "tau", "cmd"]
            sock.sendall(encode({"id": 1, "cmd": "monitor", "args": {"signals": signals, "rate_hz": 500}}))
            tally.add("requests")
            if self.s.stop.wait(STALL_HOLD_S):
                return
            excess = self.s.excess_connections()
            if excess > 0:
                tally.note(
                    "stalled_kept",
                    f"{STALL_HOLD_S:g} s after a client stopped reading, the command daemon still "
                    f"holds {excess} connection(s) more than this soak's clients",
                )
            tally.add("stalled")
        except OSError as e:
            tally.note("client_failed", f"stalled client: {e}")
        finally:
            sock.close()
            del self.stalled[me]

    def close(self) -> None:
        for t in self.stall_threads:
            t.join(timeout=10)
        for p in self.procs:
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
        self.errlog.close()


class HostileLogs(Worker):
    """Every `--hostile-every-s` (half a period after the hostile aborts): a log of 12,000
    signals, `status` timed through it; in a small log directory, the files checked after it
    filled the disk, then removed (see `soak_hostile`)."""

    def __init__(self, soak: Soak) -> None:
        super().__init__("hostile-logs", soak.stop, soak.fatal)
        self.s = soak

    def work(self) -> None:
        every, tally = self.s.args.hostile_every_s, self.s.tally
        if not every:
            return
        small = self.s.small_logs
        if self.stop.wait(every / 2):
            return
        while True:
            self.s.meter.mark("hostile log")
            r = huge_log(self.s.sock, self.stop, self.s.opened)
            tally.add("hostile_logs")
            tally.time("hostile_status_s", r["slowest_status_s"])
            if r["slowest_status_s"] > STATUS_LIMIT_S:
                tally.note("status_stalled", f"status took {r['slowest_status_s']:.2f} s during a huge log")
            if not r["ended"]:
                tally.note("log_not_ended", str(r.get("error")))
            elif r.get("error"):
                tally.add("logs_ended_full")
            if small is not None:
                time.sleep(0.5)  # the command daemon has closed the files
                for problem in unreadable_log_files(small):
                    tally.note("log_files_broken", problem)
                empty(small)
            if self.stop.wait(every):
                return


class Sampler(Worker):
    """Process statistics every `--sample-s`."""

    def __init__(self, soak: Soak) -> None:
        super().__init__("sampler", soak.stop, soak.fatal)
        self.s = soak

    def work(self) -> None:
        s = self.s
        while True:
            ours = s.ours()
            s.samples.append(sample(s.rt_pid, s.sock, time.monotonic() - s.t0, ours))
            if self.stop.wait(s.args.sample_s):
                return


# ---- the soak ------------------------------------------------------------------------------------
class Soak:
    def __init__(
        self, args: argparse.Namespace, sock: str, rt_pid: int, tel: TelemetryBlock, tmp: Path
    ) -> None:
        self.args = args
        self.sock = sock
        self.rt_pid = rt_pid
        self.tel = tel
        self.tmp = tmp
        self.small_logs: Path | None = args.small_log_path
        self.mission = Path(args.mission).resolve()
        self.overrun_limit = read_robot_config(args.config).daemon.overrun_limit
        self.stop = threading.Event()
        self.fatal: list[str] = []  # why a worker ended the soak
        self.dumps = 0
        self.tally = Tally()
        self.samples: list[Sample] = []
        self.meter = TickMeter(tel, self.stop, self.fatal)
        self.t0 = time.monotonic()
        self.operator = Operator(self)
        self.tuner = Tuner(self)
        self.monitors = Monitors(self)
        self.sampler = Sampler(self)
        self.hostile_logs = HostileLogs(self)
        self.control_clients = read_robot_config(args.config).daemon.control_clients

    def dump_ticks(self) -> Path | None:
        """The whole tick ring (its last `TICK_RING_S`), as CSV in the daemon's folder (5 at most)."""
        self.dumps += 1
        if self.dumps > 5:
            return None
        recs = RingReader(self.tel.ticks, self.tel.header, H.TICK_HEAD, from_now=False).poll()
        joints = range(self.tel.dof)
        header = [*TICK_FIELDS, *(f"{v}.{j}" for v in TICK_VECTORS for j in joints)]
        path = self.tmp / f"ticks-{self.dumps}.csv"
        np.savetxt(path, recs, delimiter=",", header=",".join(header), comments="", fmt="%.9g")
        return path

    def latest_task(self) -> float:
        head = int(self.tel.header[H.TICK_HEAD])
        return float(self.tel.ticks[(head - 1) % self.tel.tick_len][T.TASK]) if head else 0.0

    def opened(self, k: int) -> None:
        """A hostile client's connections opened (+k) or closed (-k): counted as the soak's own."""
        self.tally.add("open", k)

    def ours(self) -> int:
        """The connections this soak holds, or may (monitor processes starting up)."""
        return self.tally.n["open"] + self.monitors.alive()

    def excess_connections(self) -> int:
        """Client connections the command daemon serves beyond those this soak holds."""
        cmdd = next((pid for pid, _ in descendants(self.rt_pid) if role_of(pid) == "cmdd"), 0)
        ours = self.ours()
        return client_connections(cmdd, self.sock) - ours if cmdd else 0

    def start(self) -> None:
        self.meter.start()
        self.sampler.start()
        self.operator.start()
        self.monitors.start()
        time.sleep(1.0)  # the first load before the tuner asks for the parameters
        self.tuner.start()
        self.hostile_logs.start()

    def close(self) -> None:
        self.stop.set()
        for t in (self.operator, self.tuner, self.monitors, self.sampler, self.hostile_logs):
            if t.ident is not None:  # started
                t.join(timeout=30)
        self.monitors.close()
        self.meter.join(timeout=5)
        self.meter.finish()
        time.sleep(1.0)  # the command daemon notices the last disconnections
        self.samples.append(sample(self.rt_pid, self.sock, time.monotonic() - self.t0, 0))

    def progress(self) -> str:
        n = self.tally.n
        t = time.monotonic() - self.t0
        last = self.samples[-1] if self.samples else None
        mem = fds = ""
        if last is not None:
            main = [r for r in ("orccadd", "cmdd", "plant") if r in last.procs]
            mem = " ".join(f"{r} {last.procs[r].rss_kb / 1024:.0f}" for r in main)
            fds = " ".join(f"{r} {last.procs[r].fds}" for r in main)
        conns = last.connections if last else -1
        failed = n["run_failed"] + n["recovery_failed"]
        return (
            f"[{int(t // 60):3d}:{int(t % 60):02d}] runs {n['runs_ok']} ok, {n['runs_faulted']} safe, "
            f"{failed} failed | faults {n['recovered']} recovered | req {n['requests']} | "
            f"{self.meter.progress()} | RSS MB {mem} | fds {fds} | conns {conns}"
        )


# ---- the report ------------------------------------------------------------------------------------
SHORT_FIT = (
    "; under 10 min that is mostly memory touched for the first time, not a leak rate: e.g. the "
    "plant's timing window, ~3 MB filled over its first 240 s"
)


def grows(v: list[int]) -> bool:
    """Steady growth: the lowest of the last third above the highest of the first third."""
    if len(v) < 6:
        return False
    k = len(v) // 3
    return min(v[-k:]) > max(v[:k])


def slope_per_h(t_s: list[float], v: list[int]) -> float:
    if len(v) < 3 or t_s[-1] - t_s[0] < 1.0:
        return float("nan")
    return float(np.polyfit(np.array(t_s) / 3600.0, np.array(v, dtype=float), 1)[0])


def report(soak: Soak, elapsed_s: float, why_end: str, log: Path) -> list[str]:
    """Print the report; return the problems (empty: the soak passed)."""
    args, n, d, samples = soak.args, soak.tally.n, soak.meter.d, soak.samples
    problems: list[str] = []
    print(
        f"\nsoak: {Path(args.config).stem} at {1 / soak.tel.period_s:g} Hz, {elapsed_s / 60:.1f} min "
        f"({why_end}); mission {soak.mission.name}; daemon log {log}"
    )
    failed = n["run_failed"]
    print(
        f"  mission runs {n['runs_ok'] + n['runs_faulted'] + failed}: {n['runs_ok']} success, "
        f"{n['runs_faulted']} ended safe by an injected fault, {failed} failed; loads {n['loads']} "
        f"({_fig(soak.tally.times['load_s'], 's', 2)})"
    )
    inj = {k: n[f"injected {k}"] for k in ("resource", "overrun", "overrun-t3")}
    print(
        f"  faults injected: resource {inj['resource']}, overrun below the limit {inj['overrun']} "
        f"(run carried on {n['overrun_carried_on']}, broken {n['overrun_broke_run']}), overrun beyond "
        f"the limit (type 3) {inj['overrun-t3']}; recovered {n['recovered']} of "
        f"{inj['resource'] + inj['overrun-t3']} (inject → reset done "
        f"{_fig(soak.tally.times['recovery_s'], 's', 2)}); recovery failures {n['recovery_failed']}"
    )
    print(
        f"  requests sent {n['requests']}: tunes {n['tunes']} ({n['tune_refused']} refused); "
        f"{args.monitors} monitors at {MONITOR_HZ:g} Hz, {n['monitor_kills']} killed and restarted, "
        f"{n['monitor_ended']} ended by themselves, {n['monitor_samples']} samples; clients that stopped "
        f"reading {n['stalled']}, still held by the daemon after {STALL_HOLD_S:g} s {n['stalled_kept']}"
    )
    print(
        f"  ticks {d.ticks} judged ({d.unjudged} torn/lost, ring reader lost {soak.meter.reader.lost}); "
        f"spontaneous missed deadlines {d.overruns} ({d.skipped} periods skipped), runs by length "
        f"{dict(sorted(d.runs.items()))}, longest {max(d.runs, default=0)}; after an operator action "
        f"(≤ {CAUSE_S:g} s): {dict(d.causes.most_common())}"
    )
    total_hdr = soak.meter.overruns[1] - soak.meter.overruns[0]
    print(
        f"  injected: {d.injected_ticks} ticks in overrun windows, {d.injected_overruns} overran "
        f"(runs {dict(sorted(d.injected_runs.items()))}); the loop's own count {total_hdr} "
        f"(this reader: {d.overruns + d.injected_overruns})"
    )
    times = soak.tally.times
    print(
        f"  hostile clients: {n['runs_aborted']} runs aborted through every place held (orccadctl abort "
        f"{_fig(times['hostile_abort_s'], 's', 2)}), {n['abort_denied']} denied; {n['hostile_logs']} logs "
        f"of 12,000 signals ({n['logs_ended_full']} ended by a full log directory), slowest status "
        f"{_fig(times['hostile_status_s'], 's', 2)}, {n['status_stalled']} over {STATUS_LIMIT_S:g} s; "
        f"files left unreadable {n['log_files_broken']}; logs that did not end {n['log_not_ended']}"
    )
    print(f"  wake-up (spontaneous ticks)  {soak.meter.wake.figures()}")
    print(f"  compute (spontaneous ticks)  {soak.meter.compute.figures()}")
    problems += _process_table(soak, samples)
    keys = (
        "run_failed", "load_failed", "recovery_failed", "monitor_ended", "stalled_kept", "tune_refused",
        "abort_denied", "status_stalled", "log_files_broken", "log_not_ended",
    )  # fmt: skip
    for key in (*keys, "client_failed"):
        for msg in soak.tally.notes.get(key, []):
            print(f"  {key}: {msg}")
    if failed:
        problems.append(f"{failed} mission runs failed")
    if n["load_failed"]:
        problems.append(f"{n['load_failed']} loads failed")
    if n["recovery_failed"]:
        problems.append(f"{n['recovery_failed']} fault recoveries failed")
    if n["overrun_broke_run"]:
        problems.append("an overrun below the limit broke a run")
    if n["monitor_ended"] or n["client_failed"]:
        problems.append(f"clients cut off: {n['monitor_ended']} monitors, {n['client_failed']} others")
    if n["stalled_kept"]:
        problems.append(f"{n['stalled_kept']} clients that stopped reading were never dropped")
    for key, what in (
        ("abort_denied", "aborts not applied through held places"),
        ("status_stalled", f"status answers slower than {STATUS_LIMIT_S:g} s during a huge log"),
        ("log_files_broken", "log files left unreadable"),
        ("log_not_ended", "logs that did not end"),
    ):
        if n[key]:
            problems.append(f"{n[key]} {what}")
    return problems


def _fig(v: list[float], unit: str, digits: int) -> str:
    if not v:
        return "none"
    a = np.array(v)
    return f"median {np.median(a):.{digits}f}, max {a.max():.{digits}f} {unit}"


def _process_table(soak: Soak, samples: list[Sample]) -> list[str]:
    """RSS, fds and sockets per process, the command daemon's connections; the problems seen."""
    problems: list[str] = []
    run, after = samples[:-1] or samples, samples[-1]  # the last one: after our clients closed
    warm = [s for s in run if s.t_s >= soak.args.warmup_s] or run
    span = warm[-1].t_s - warm[0].t_s
    print(
        f"  processes ({len(run)} samples every {soak.args.sample_s:g} s; RSS growth fitted over "
        f"{span:.0f} s after {soak.args.warmup_s:g} s" + (SHORT_FIT if span < 600 else "") + "):"
    )
    print(f"    {'process':<26} {'pids':<8} {'RSS kB start/end':>17} {'kB/h':>7} {'fds start/end/max':>18} "
          f"{'sockets s/e/max':>16}")  # fmt: skip
    for role in dict.fromkeys(r for s in run for r in s.procs):
        have = [s.procs[role] for s in run if role in s.procs]
        pids = ",".join(str(p) for p in sorted({p.pid for p in have}))
        if role in TRANSIENT or role not in run[0].procs:
            n_pids, rss_max = len({p.pid for p in have}), max(p.rss_kb for p in have)
            print(f"    {role:<26} {n_pids} seen in {len(have)} samples, RSS max {rss_max} kB")
            continue
        w = [(s.t_s, s.procs[role]) for s in warm if role in s.procs]
        rate = slope_per_h([t for t, _ in w], [p.rss_kb for _, p in w])
        rss, fds, socks = ([getattr(p, k) for p in have] for k in ("rss_kb", "fds", "sockets"))
        print(
            f"    {role:<26} {pids:<8} {rss[0]:>8}/{rss[-1]:<8} {rate:>7.0f} "
            f"{fds[0]:>7}/{fds[-1]}/{max(fds):<7} {socks[0]:>7}/{socks[-1]}/{max(socks)}"
        )
        missing = [s.t_s for s in run if role not in s.procs]
        if "," in pids or missing or (role not in after.procs and "orccadd" in after.procs):
            gone = f", missing from {missing[0]:.0f} s" if missing else ""
            problems.append(f"{role} died or was restarted (pids {pids}{gone})")
        if grows([p.fds for _, p in w]):
            problems.append(f"{role}: open fds grew steadily ({fds[0]} → {fds[-1]})")
    conns = [s.connections for s in run]
    print(
        f"  command daemon client connections start/end/max {conns[0]}/{conns[-1]}/{max(conns)}; beyond "
        f"this soak's clients at most {max(s.connections - s.ours for s in warm)}; after they all closed: "
        f"{after.connections if after.connections >= 0 else 'n/a (no command daemon)'}"
    )
    if grows([s.connections for s in warm]):
        problems.append(f"command daemon connections grew steadily ({conns[0]} → {conns[-1]})")
    if after.connections > 0:
        problems.append(f"{after.connections} connections still served after every client closed")
    _over_time(run)
    return problems


def _over_time(run: list[Sample]) -> None:
    """Up to 12 samples, evenly spread: RSS (MB) / fds of the long-lived processes, connections."""
    main = [r for r in ("orccadd", "cmdd", "plant") if r in run[0].procs]
    print("  over time:   t_s " + "".join(f"{r[:16]:>17}" for r in main) + "   connections")
    for i in sorted({round(i * (len(run) - 1) / 11) for i in range(12)}):
        s = run[i]
        cells = "".join(
            f"{f'{s.procs[r].rss_kb / 1024:.1f}/{s.procs[r].fds}' if r in s.procs else '-':>17}" for r in main
        )
        print(f"             {s.t_s:5.0f}{cells}   {s.connections:>5}")


# ---- config, main ------------------------------------------------------------------------------------
def config_at_500hz(robot: str, mission: Path, log_dir: Path | None = None) -> Path:
    """The robot config, or a copy at 500 Hz (relative paths made absolute, the mission's folder
    among `daemon.mission_dirs`, `log_dir` if given) if it runs at another rate, cannot load the
    mission or must log elsewhere."""
    path = Path(robot) if robot.endswith(".toml") else ROOT / f"configs/robots/{robot}.toml"
    cfg = read_robot_config(path)
    dirs = [cfg.resolve(x) for x in cfg.daemon.mission_dirs]
    inside = any(mission.resolve().is_relative_to(x) for x in dirs)
    if abs(cfg.control_period_s - PERIOD_S) < 1e-12 and inside and log_dir is None:
        return path
    text = path.read_text()
    text = re.sub(r"(?m)^control_period_s\s*=.*$", f"control_period_s = {PERIOD_S}", text)
    text = re.sub(r'"(\.\.?/[^"]*)"', lambda m: f'"{(path.parent / m.group(1)).resolve()}"', text)
    text = re.sub(r"(?m)^(hold_task|mission_dirs|task_dirs)\s*=.*$", "", text)
    dirs_toml = ", ".join(f'"{x}"' for x in [*dirs, mission.resolve().parent])
    tasks_toml = ", ".join(f'"{cfg.resolve(x)}"' for x in cfg.daemon.task_dirs)
    daemon = f'hold_task = "{cfg.resolve(cfg.daemon.hold_task)}"\nmission_dirs = [{dirs_toml}]\n'
    daemon += f"task_dirs = [{tasks_toml}]\n"
    if log_dir is not None:
        text = re.sub(r"(?m)^log_dir\s*=.*$", "", text)
        daemon += f'log_dir = "{log_dir}"\n'
    text = (
        text.replace("\n[daemon]\n", f"\n[daemon]\n{daemon}")
        if "\n[daemon]\n" in text
        else f"{text}\n[daemon]\n{daemon}"
    )
    out = Path(tempfile.mkdtemp(prefix="orccadd-soak-")) / path.name
    out.write_text(text)
    print(
        f"soak: {path} copied to {out} (at {PERIOD_S:g} s, {mission.name}'s folder allowed, logs: {log_dir})"
    )
    return out


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    how_long = ap.add_mutually_exclusive_group(required=True)
    how_long.add_argument("--hours", type=float)
    how_long.add_argument("--minutes", type=float)
    ap.add_argument(
        "--robot", default="sim-ur5e", help="a name in configs/robots or a .toml path (run at 500 Hz)"
    )
    ap.add_argument("--mission", default=str(MISSION), help="a mission that ends by itself (success)")
    ap.add_argument("--sample-s", type=float, default=10.0, help="process statistics every … s")
    ap.add_argument("--progress-s", type=float, default=30.0, help="a progress line every … s")
    ap.add_argument("--warmup-s", type=float, help="growth fitted after (default: 20 %% of the run, ≤ 300 s)")
    ap.add_argument("--reload-every", type=int, default=10, help="load the mission again every … runs")
    ap.add_argument("--fault-first-s", type=float, default=45.0)
    ap.add_argument("--fault-every-s", type=float, default=120.0, help="inject fault=resource every … s")
    ap.add_argument("--overrun-first-s", type=float, default=100.0)
    ap.add_argument("--overrun-every-s", type=float, default=300.0, help="inject fault=overrun every … s")
    ap.add_argument("--monitors", type=int, default=5)
    ap.add_argument("--monitor-life-s", type=float, default=120.0, help="each monitor killed after … s")
    ap.add_argument("--stall-every-s", type=float, default=60.0, help="a client that never reads (0: none)")
    ap.add_argument(
        "--hostile-every-s", type=float, default=300.0, help="hostile clients every … s (0: none)"
    )
    ap.add_argument(
        "--small-log-dir-kb",
        type=int,
        default=512,
        help="the daemon's logs on a tmpfs this small (root; 0: no)",
    )
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    args.duration_s = 3600.0 * args.hours if args.hours is not None else 60.0 * args.minutes
    if args.warmup_s is None:
        args.warmup_s = min(300.0, 0.2 * args.duration_s)
    if args.reload_every < 1 or args.sample_s <= 0 or args.duration_s <= 0:
        ap.error("--reload-every, --sample-s and the duration must be positive")
    return args


def leftovers(samples: list[Sample], wait_s: float = 10.0) -> list[str]:
    """Processes seen during the soak still there `wait_s` after the daemon ended."""
    seen = {p.pid: r for s in samples for r, p in s.procs.items()}
    end = time.monotonic() + wait_s
    while True:
        left = [f"{role} ({pid})" for pid, role in seen.items() if _running(pid)]
        if not left or time.monotonic() > end:
            return left
        time.sleep(0.2)


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def main() -> int:
    args = parse_args()
    small = SmallLogDir(args.small_log_dir_kb)
    try:
        return _main(args, small)
    finally:
        small.close()


def _main(args: argparse.Namespace, small: SmallLogDir) -> int:
    args.small_log_path = small.path
    args.config = str(config_at_500hz(args.robot, Path(args.mission), small.path))
    with running_daemon(Path(args.config), "--allow-fault-injection", new_session=True) as d:
        with Client(d.socket) as c:
            tel = TelemetryBlock.attach(str(c.call("describe")["telemetry"]))
        try:
            soak = Soak(args, d.socket, d.proc.pid, tel, d.tmp)
            print(f"soak: {args.config}, {args.duration_s / 60:g} min, orccadd pid {d.proc.pid}", flush=True)
            why_end = run(soak, d.proc)
            problems = report(soak, time.monotonic() - soak.t0, why_end, d.log)
        finally:
            tel.close()
        code = d.proc.poll()
    # the daemon was stopped (SIGTERM) at the end of the block above
    if code is not None:
        problems.append(f"orccadd exited during the soak (code {code})")
    if why_end.startswith("ended early"):
        problems.append(why_end)
    left = leftovers(soak.samples)
    print(f"  after teardown: {'left running: ' + ', '.join(left) if left else 'no process left'}")
    if left:
        problems.append(f"left running after teardown: {', '.join(left)}")
    print("  verdict: " + ("PASS" if not problems else "FAIL: " + "; ".join(problems)))
    return 1 if problems else 0


def run(soak: Soak, daemon: subprocess.Popen[bytes]) -> str:
    """The soak, until its end, Ctrl-C/SIGTERM, or a fatal failure; why it ended. Everything it
    started is stopped on return."""
    interrupted = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        interrupted.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    try:
        soak.start()
        end = soak.t0 + soak.args.duration_s
        next_print = soak.t0 + soak.args.progress_s
        while time.monotonic() < end:
            if interrupted.is_set():
                return "interrupted"
            if soak.stop.is_set():
                return f"ended early: {'; '.join(soak.fatal) or 'stopped'}"
            if daemon.poll() is not None:
                return f"ended early: orccadd exited with code {daemon.returncode}"
            if time.monotonic() >= next_print:
                print(soak.progress(), flush=True)
                next_print += soak.args.progress_s
            interrupted.wait(min(1.0, max(0.0, end - time.monotonic())))
        return "as planned"
    finally:
        soak.close()


if __name__ == "__main__":
    raise SystemExit(main())
