"""Replay and compare on long runs, and what the full log costs.

- **record**: orccadd on sim-ur5e (500 Hz) runs benchmarks/missions/replay_soak.mission (Reach
  and Back in a loop until Stop) for `--minutes`, logged the ordinary way (`log start` with no
  signal names: everything compare and replay need); twice, runs A and B.
- **replay**: `orccadctl replay A.mcap` in a child process: its wall time, the speed as a
  multiple of real time (the replayed windows' length in the run over the replay's time), its
  peak memory (the child's maximum resident set), and whether the commands were identical.
- **compare**: `orccadctl compare A.mcap B.mcap`: wall time and peak memory.
- **log cost**: the command daemon's CPU time per second of log and the MCAP's bytes per second,
  for the default selection (runs A and B) and, in a run of `--cost-s`, for `q dq tau cmd` alone.

Usage: `python benchmarks/replay.py [--minutes 10] [--cost-s 60] [--reuse]` (root, for SCHED_FIFO;
`--reuse`: replay and compare the runs a run before recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from harness import ROOT, running_daemon

from orccadd.ctl.client import Client

MISSION = ROOT / "benchmarks/missions/replay_soak.mission"
FOUR = ["q", "dq", "tau", "cmd"]


@dataclass
class Logged:
    mcap: Path
    seconds: float
    cmdd_cpu_s: float

    @property
    def bytes_per_s(self) -> float:
        return self.mcap.stat().st_size / self.seconds

    @property
    def cpu_share(self) -> float:
        return self.cmdd_cpu_s / self.seconds


def cpu_s(pid: int) -> float:
    """User + system CPU time of process `pid` (s)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def command_daemon(root: int) -> int:
    """The pid of the command daemon among `root`'s descendants."""
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            cmdline = (p / "cmdline").read_bytes().replace(b"\0", b" ")
            ppid = int((p / "stat").read_text().rpartition(")")[2].split()[1])
        except (OSError, ValueError):
            continue
        if b"orccadd.cmdd" in cmdline and ppid in (root, *_children(root)):
            return int(p.name)
    raise SystemExit(f"no command daemon under pid {root}")


def _children(pid: int) -> list[int]:
    try:
        return [int(x) for x in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def record(out: Path, seconds: float, signals: list[str] | None) -> Logged:
    """One run of the soak mission for `seconds`, logged; its MCAP copied to `out`."""
    with running_daemon() as d, Client(d.socket, timeout_s=120) as c:
        c.call("load", path=str(MISSION))
        cmdd = command_daemon(d.proc.pid)
        args = {"signals": signals} if signals else {}
        c.call("log", action="start", name=f"{out.stem}-{os.getpid()}.csv", **args)
        cpu0, t0 = cpu_s(cmdd), time.monotonic()
        c.call("start")
        while time.monotonic() - t0 < seconds:
            s = c.call("status")
            if s["state"] != "running":
                raise SystemExit(f"the mission ended early ({s['result']}): {s['log']}")
            time.sleep(1.0)
        c.call("send", input="Stop")
        time.sleep(0.5)
        summary = c.call("log", action="stop")
        took, cpu = time.monotonic() - t0, cpu_s(cmdd) - cpu0
    mcap = Path(summary["mcap"][0])
    out.write_bytes(mcap.read_bytes())
    return Logged(out, took, cpu)


# orccadctl in a child that reports its own peak resident memory on its last stderr line
WRAPPED = (
    "import resource, sys\n"
    "from orccadd.cli import orccadctl_main\n"
    "code = orccadctl_main(sys.argv[1:])\n"
    "print('maxrss_kib', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\n"
    "sys.exit(code)\n"
)


def timed(argv: list[str]) -> tuple[float, float, int, str]:
    """`orccadctl ARGV` in a child: wall time (s), its peak memory (MiB), exit code, stdout."""
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-c", WRAPPED, *argv], capture_output=True, text=True)
    took = time.monotonic() - t0
    last = (r.stderr.strip().splitlines() or [""])[-1].split()
    peak = int(last[1]) / 1024 if last[:1] == ["maxrss_kib"] else float("nan")
    return took, peak, r.returncode, r.stdout


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="each long run's length")
    ap.add_argument("--cost-s", type=float, default=60.0, help="the run logged with q dq tau cmd alone")
    ap.add_argument("--out", default="/tmp/orccadd-replay-bench", help="where the runs' MCAPs go")
    ap.add_argument("--reuse", action="store_true", help="replay and compare the runs already in --out")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    mcap_a, mcap_b = out / "a.mcap", out / "b.mcap"
    if not (a.reuse and mcap_a.is_file() and mcap_b.is_file()):
        print(f"recording two runs of {a.minutes:g} min (sim-ur5e, 500 Hz, {MISSION.name}), default log")
        run_a = record(mcap_a, a.minutes * 60, None)
        run_b = record(mcap_b, a.minutes * 60, None)
        print(f"recording {a.cost_s:g} s logged with {' '.join(FOUR)} alone")
        four = record(out / "four.mcap", a.cost_s, FOUR)
        print("\nlog cost (the command daemon's CPU share; the MCAP's growth):")
        for name, lg in (("default (A)", run_a), ("default (B)", run_b), ("q dq tau cmd", four)):
            print(f"  {name:<13} {100 * lg.cpu_share:5.1f} % of a core  {lg.bytes_per_s / 1e6:6.2f} MB/s")
        ratio = run_a.cpu_share / four.cpu_share if four.cpu_share else float("nan")
        size = run_a.bytes_per_s / four.bytes_per_s
        print(f"  default / four vectors: CPU x{ratio:.2f}, size x{size:.2f}")
    mb = mcap_a.stat().st_size / 1e6
    took, mem, code, text = timed(["replay", "--json", str(mcap_a)])
    rep = json.loads(text.splitlines()[0]) if text.startswith("{") else {}
    run_s = float(rep.get("run_s", 0.0))
    print(f"\nreplay of A ({mb:.0f} MB, {run_s:.0f} s of task windows): exit {code}, {took:.1f} s wall")
    print(f"  {run_s / took:.1f}x real time (whole command, reading the MCAP included); in the law alone:")
    law_s = max(float(rep.get("elapsed_s", 0.0)), 1e-9)
    print(f"  {law_s:.1f} s, {run_s / law_s:.0f}x real time")
    print(f"  peak memory {mem:.0f} MiB; identical: {rep.get('identical')}")
    took, mem, code, _ = timed(["compare", str(mcap_a), str(mcap_b)])
    print(f"\ncompare A B: exit {code}, {took:.1f} s wall, peak memory {mem:.0f} MiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
