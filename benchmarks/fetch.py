"""Fetching a log over the cell: its throughput, and what it costs the control loop.

One daemon (a simulated UR5e at 500 Hz, a Zenoh peer on a loopback TLS endpoint with a test
certificate, as in benchmarks/cell_zenoh.py) logs its default signals for `--log-s` seconds while
it holds: a large log (CSV and MCAP). Then the loop's wake-up latency of every tick (from its
telemetry ring) for `--window-s` seconds with nothing else running; for as long while a console
fetches that log again and again over the cell (`orccadctl --robot bench-a fetch LOG -o DIR`, a
process each time, the last one let finish); and for as long without again (this VM's noise
drifts within minutes: the two runs without bracket the one with). Then one fetch over the
daemon's unix socket, for comparison.

Printed: the log's files and sizes; the throughput of the fetches over the cell (median, min) and
of the one over the socket, in MB/s of the whole orccadctl process (its start and, over the cell,
the session's opening included; a bare `logs` over the cell is timed too, to show that part);
wake-up latency median / p99 / max without and with the fetch, and the ratio of the p99 with to
the mean of the p99s without. Target: <= 1.10 (the real-time threads touch neither Zenoh nor the
disk). Exits 0 after printing; nonzero only if something fails.

Usage: `python benchmarks/fetch.py [--log-s 60] [--window-s 20] [--json]` (root, for SCHED_FIFO).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from cell import POLL_S, recording
from cell_zenoh import CELL, WARM_UP_S, daemons, endpoints_of, wake_p99s
from harness import figures

from orccadd.cellnet.certs import make_cell_certs
from orccadd.launch import DaemonProcess
from orccadd.wire.schema import T
from tests.cellnet.conftest import console_file

ROBOT = "bench-a"
ORCCADCTL = [sys.executable, "-m", "orccadd.cli"]


def fetch_argv(via: list[str], sock: str, log: str, out: Path) -> list[str]:
    """orccadctl's fetch of `log` into `out`, over the cell (`via`: --cell FILE --robot R) or,
    without `via`, over the socket `sock`."""
    where = ["--socket", sock] if not via else []
    return [*ORCCADCTL, *via, "fetch", *where, log, "-o", str(out), "--force", "--json"]


def fetched_files(stdout: str) -> dict[str, int]:
    return {Path(f["file"]).name: int(f["bytes"]) for f in json.loads(stdout)["fetched"]}


def timed(argv: list[str]) -> tuple[subprocess.CompletedProcess[str], float]:
    t0 = time.monotonic()
    r = subprocess.run(argv, capture_output=True, text=True, timeout=600)  # killed on any exception
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(argv[2:])} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    return r, time.monotonic() - t0


def fetch_window(d: DaemonProcess, argv: list[str], window_s: float) -> tuple[np.ndarray, list[float]]:
    """The wake-up latency of every tick while `argv` (a fetch) runs again and again for
    `window_s` (the last one let finish), and each fetch's MB/s."""
    rates: list[float] = []
    proc: subprocess.Popen[str] | None = None
    with d.client() as c, recording(c) as (rec, poll):
        end = time.monotonic() + window_s
        try:
            while proc is not None or time.monotonic() < end:
                if proc is None:
                    t0 = time.monotonic()
                    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                try:
                    out, err = proc.communicate(timeout=POLL_S)
                except subprocess.TimeoutExpired:
                    poll()
                    continue
                if proc.returncode != 0:
                    raise SystemExit(f"fetch over the cell failed ({proc.returncode}):\n{err[-2000:]}")
                rates.append(sum(fetched_files(out).values()) / 1e6 / (time.monotonic() - t0))
                proc = None
                poll()
        finally:
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    return rec.resource_ticks(0)[:, T.WAKE_US], rates


@contextlib.contextmanager
def daemon(tmp: Path) -> Iterator[DaemonProcess]:
    """cell_zenoh's daemon, its directory (the big log in it) removed once it is stopped."""
    home: list[Path] = []
    try:
        with daemons([ROBOT], make_cell_certs(tmp / "certs", ["console", ROBOT])) as (d,):
            home.append(Path(d.socket).parent.parent)
            yield d
    finally:
        for h in home:
            shutil.rmtree(h, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else "")
    ap.add_argument("--log-s", type=float, default=60.0, help="seconds logged: the log fetched")
    ap.add_argument("--window-s", type=float, default=20.0, help="seconds recorded each way")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    a = ap.parse_args()
    with (
        tempfile.TemporaryDirectory(prefix="orccadd-fetch-bench-") as t,
        daemon(Path(t)) as d,
    ):
        tmp, certs = Path(t), Path(t) / "certs"
        console = console_file(tmp, CELL, "console", certs, endpoints_of([d]), daemons=(ROBOT,))
        via = ["--cell", str(console), "--robot", ROBOT]
        time.sleep(WARM_UP_S)
        log = d.call("log", action="start")["file"]
        time.sleep(a.log_s)
        d.call("log", action="stop")
        listed = next(lg for lg in d.call("logs")["logs"] if lg["name"] == Path(log).name)
        name = listed["name"]
        r, socket_s = timed(fetch_argv([], d.socket, name, tmp / "by-socket"))
        files = fetched_files(r.stdout)
        total_mb = sum(files.values()) / 1e6
        _, logs_s = timed([*ORCCADCTL, *via, "logs"])
        without = wake_p99s([d], a.window_s)[0]
        with_fetch, rates = fetch_window(d, fetch_argv(via, "", name, tmp / "by-cell"), a.window_s)
        again = wake_p99s([d], a.window_s)[0]
        overruns = int(d.status()["overruns"])
    p99s = {k: float(np.percentile(v, 99)) for k, v in (("without", without), ("again", again))}
    ratio = float(np.percentile(with_fetch, 99)) / ((p99s["without"] + p99s["again"]) / 2)
    verdict = "met" if ratio <= 1.10 else "NOT met"
    if a.json:
        wake = {"without": without, "with fetch": with_fetch, "without again": again}
        print(
            json.dumps(
                {
                    "log": {"files": files, "logs_size": listed["size"], "seconds": a.log_s},
                    "cell_mb_s": rates,
                    "socket_mb_s": total_mb / socket_s,
                    "cell_logs_s": logs_s,
                    "wake_us": {
                        k: dict(
                            zip(
                                ("median", "p99", "max", "n"),
                                [*np.percentile(v, [50, 99, 100]), len(v)],
                                strict=True,
                            )
                        )
                        for k, v in wake.items()
                    },
                    "p99_ratio": ratio,
                    "overruns_since_start": overruns,
                },
                indent=1,
            )
        )
        return 0
    sizes = ", ".join(f"{f} {b / 1e6:.1f} MB" for f, b in files.items())
    print(f"log: {a.log_s:g} s of the default signals at 500 Hz: {sizes} ({total_mb:.1f} MB)")
    print(
        f"fetch over the cell: {len(rates)} fetches in the window, median {np.median(rates):.1f}  "
        f"min {min(rates):.1f} MB/s  (a bare `logs` over the cell: {logs_s:.2f} s)"
        if rates
        else "fetch over the cell: none finished"
    )
    print(f"fetch over the socket: {total_mb / socket_s:.1f} MB/s ({socket_s:.2f} s)")
    print(f"wake-up without a fetch:       {figures(without, 'µs')}")
    print(f"wake-up while fetching:        {figures(with_fetch, 'µs')}")
    print(f"wake-up without a fetch again: {figures(again, 'µs')}")
    print(
        f"p99 while fetching / the mean p99 without: {ratio:.2f} (target <= 1.10: {verdict}); the runs "
        f"without differ by {100 * (max(p99s.values()) / min(p99s.values()) - 1):.0f} %"
    )
    print(f"the loop's overruns since it started (the logging included): {overruns}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
