"""What the daemon benchmarks share: a running orccadd on a private socket, and figures."""

from __future__ import annotations

import contextlib
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orccadd.launch import DaemonProcess

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # the CANopen rig of the tests (bus hub + simulated drives)
    sys.path.insert(0, str(ROOT))
UR5E = ROOT / "configs/robots/sim-ur5e.toml"


@dataclass
class RunningDaemon:
    proc: subprocess.Popen[bytes]
    socket: str
    tmp: Path
    log: Path


@contextlib.contextmanager
def running_daemon(config: Path = UR5E, *extra: str, new_session: bool = False) -> Iterator[RunningDaemon]:
    """`orccadd --config CONFIG` with its command daemon, stopped (SIGTERM) on exit.

    `new_session`: in a session of its own, so a Ctrl-C at the terminal reaches the benchmark
    alone, which then stops the daemon itself (after its own teardown)."""
    tmp = Path(tempfile.mkdtemp(prefix="orccadd-bench-"))
    d = DaemonProcess(config, tmp / "orccadd.sock", tmp / "orccadd.log", *extra, new_session=new_session)
    try:
        yield RunningDaemon(d.proc, d.socket, tmp, d.log)
    finally:
        d.stop()


def config_with(config: Path, tmp: Path, daemon_lines: str) -> Path:
    """A copy of `config` in `tmp` with lines added to its [daemon] table (its relative paths
    made absolute, so they still name the shipped files)."""
    text = config.read_text().replace('"../', f'"{config.parent.parent}/')
    if "hold_task" not in text:  # the defaults are relative to the config too
        daemon_lines += f'\nhold_task = "{config.parent.parent}/tasks/hold.toml"'
    if "task_dirs" not in text:
        daemon_lines += f'\ntask_dirs = ["{config.parent.parent}/tasks"]'
    text = text.replace("\n[daemon]\n", f"\n[daemon]\n{daemon_lines}\n", 1)
    out = tmp / config.name
    out.write_text(text)
    return out


def targets_for(lo: np.ndarray, hi: np.ndarray, home: np.ndarray) -> list[list[float]]:
    """Three goals well inside the limits: home, and an eighth of the range either side of it."""
    span = np.minimum(hi - lo, 2 * np.pi) / 8
    lo, hi = lo + span / 2, hi - span / 2
    return [home.tolist(), np.clip(home + span, lo, hi).tolist(), np.clip(home - span, lo, hi).tolist()]


def figures(values: np.ndarray | list[float], unit: str, digits: int = 1) -> str:
    """`median … p99 … max …` of `values` in `unit`."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return "no samples"
    med, p99 = np.percentile(v, [50, 99])
    f = f"{{:.{digits}f}}"
    return f"median {f.format(med)}  p99 {f.format(p99)}  max {f.format(v.max())} {unit}  (n={v.size})"


def cyclictest(period_s: float, duration_s: float, priority: int) -> np.ndarray | None:
    """Wake-up latencies (µs) of Debian's `cyclictest` (rt-tests), one thread, from its histogram.

    None (and a note on stderr) when cyclictest is not installed.
    """
    exe = shutil.which("cyclictest")
    if exe is None:
        print("cyclictest not found (apt-get install rt-tests): no baseline", file=sys.stderr)
        return None
    loops = max(1, int(duration_s / period_s))
    cmd = [exe, "-m", "-q", f"-p{priority}", f"-i{int(period_s * 1e6)}", f"-l{loops}", "-h20000"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=duration_s * 3 + 30).stdout
    values, counts = [], []
    for line in out.splitlines():
        m = re.match(r"^(\d+)\s+(\d+)\s*$", line)
        if m and int(m.group(2)):
            values.append(int(m.group(1)))
            counts.append(int(m.group(2)))
    if not values:
        print(f"cyclictest printed no histogram:\n{out[-500:]}", file=sys.stderr)
        return None
    samples = np.repeat(np.array(values, dtype=float), counts)
    max_m = re.search(r"# Max Latencies:\s+(\d+)", out)
    if max_m and float(max_m.group(1)) > samples[-1]:  # beyond the histogram's range
        samples[-1] = float(max_m.group(1))
    return samples
