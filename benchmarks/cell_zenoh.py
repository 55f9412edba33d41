"""A cell of daemons over Zenoh: remote signal latency, what the cell costs the control loops, and
how the console scales. Every daemon is a real orccadd (its own processes, a simulated UR5e at
500 Hz) and a Zenoh peer on a loopback TLS endpoint with a test certificate.

- **latency**: daemon A runs benchmarks/missions/cell_ping_a.mission (each `send Go` emits
  `Ping`, an output to the cell), daemon B cell_ping_b.mission (`input Ping from "bench-a"`). The
  latency of one signal is B's instant that took it minus A's instant that emitted it, both from
  the daemons' traces (CLOCK_MONOTONIC, one machine). Against, in the same run, a bare Zenoh put ->
  subscriber callback between two processes over the same kind of link (loopback TLS). Target:
  ratio of medians (and of p99s) <= 1.5.
- **load**: three daemons, each loop's wake-up latency (every tick, from its telemetry ring)
  without `[cell]`, then with it (joint states at 50 Hz, status, events) and a console
  subscribed to everything the cell publishes. Target: each daemon's p99 with the cell within
  10 % of its p99 without (the real-time threads never touch Zenoh).
- **scale**: cells of 1, 3 and 8 daemons: the console's refresh (`cell status`: every daemon's
  status asked at once) and a command's round trip (`describe`, answered by the real-time
  process) from the console, median / p99 / max.

Usage: `python benchmarks/cell_zenoh.py [--rounds 300] [--duration-s 30] [--sizes 1,3,8]
[--parts latency,load,scale]` (root, for SCHED_FIFO).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from cell import recording, run_for
from harness import ROOT, UR5E, config_with, figures

from orccadd.cellnet.certs import make_cell_certs
from orccadd.cellnet.console import CellConsole
from orccadd.config.cellnet import load_cellnet
from orccadd.launch import DaemonProcess
from orccadd.wire.schema import T

MISSIONS = ROOT / "benchmarks/missions"
CELL = "bench"
WARM_UP_S = 5.0  # after the daemons are up, before recording


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def cell_table(name: str, port: int, connect: list[str], certs: Path, peers: list[str]) -> str:
    return textwrap.dedent(f"""
        [cell]
        name = "{CELL}"
        robot = "{name}"
        listen = ["tls/127.0.0.1:{port}"]
        connect = {json.dumps(connect)}
        ca = "{certs / "ca.pem"}"
        certificate = "{certs / f"{name}.pem"}"
        private_key = "{certs / f"{name}.key"}"
        control = {json.dumps(["console", *[p for p in peers if p != name]])}
        """)


@contextlib.contextmanager
def daemons(
    names: list[str], certs: Path, cell: bool = True, cell_lines: str = ""
) -> Iterator[list[DaemonProcess]]:
    """A daemon per name on sim-ur5e, each a peer of the cell (connected to those before it);
    `cell_lines` added to each one's `[cell]` table."""
    tmp = Path(tempfile.mkdtemp(prefix="orccadd-cell-bench-"))
    running: list[DaemonProcess] = []
    endpoints: list[str] = []
    try:
        for name in names:
            d = tmp / name
            d.mkdir()
            config = config_with(UR5E, d, "")  # its missions: configs/ and benchmarks/missions
            text = config.read_text()
            if cell:
                port = free_port()
                text += cell_table(name, port, list(endpoints), certs, names) + cell_lines
                endpoints.append(f"tls/127.0.0.1:{port}")
            config.write_text(text)
            running.append(DaemonProcess(config, d / "orccadd.sock", d / "orccadd.log", up_timeout_s=120.0))
        yield running
    finally:
        for p in running:
            p.stop()


def console_for(certs: Path, connect: list[str]) -> CellConsole:
    raw = {
        "name": CELL,
        "robot": "console",
        "connect": connect,
        "ca": str(certs / "ca.pem"),
        "certificate": str(certs / "console.pem"),
        "private_key": str(certs / "console.key"),
    }
    return CellConsole(load_cellnet(raw, "<benchmark>", "console"))


def endpoints_of(ds: list[DaemonProcess]) -> list[str]:
    out = []
    for d in ds:
        text = Path(d.proc.args[d.proc.args.index("--config") + 1]).read_text()  # type: ignore[union-attr,arg-type]
        out += [line.split('"')[1] for line in text.splitlines() if line.startswith("listen = [")]
    return out


# ---- latency ------------------------------------------------------------------------------------
def run_latency(certs: Path, rounds: int, rate_hz: float) -> list[str]:
    with daemons(["bench-a", "bench-b"], certs) as (a, b):
        b.call("load", path=str(MISSIONS / "cell_ping_b.mission"))
        b.call("start")
        a.call("load", path=str(MISSIONS / "cell_ping_a.mission"))
        a.call("start")
        time.sleep(1.0)
        with a.client() as c:
            for _ in range(rounds):
                c.call("send", input="Go")
                time.sleep(1.0 / rate_hz)
        time.sleep(1.0)
        sent = [
            e["t_s"] for e in a.call("events", last=100_000)["events"] if "emit Ping" in e.get("actions", [])
        ]
        took = [e["t_s"] for e in b.call("events", last=100_000)["events"] if e.get("inputs") == ["Ping"]]
        bare = bare_zenoh(certs, rounds, rate_hz)  # with the daemons still running: the same load
    n = min(len(sent), len(took))
    ours = (np.asarray(took[:n]) - np.asarray(sent[:n])) * 1e6
    lines = [
        f"latency: {len(sent)} Pings emitted by A, {len(took)} taken by B ({len(sent) - len(took)} missed)",
        f"  emit on A -> reaction on B: {figures(ours, 'µs')}",
        f"  bare Zenoh put -> callback (two processes, loopback TLS): {figures(bare, 'µs')}",
    ]
    if len(ours) and len(bare):
        m = np.median(ours) / np.median(bare)
        p = np.percentile(ours, 99) / np.percentile(bare, 99)
        met = "met" if max(m, p) <= 1.5 else "NOT met"
        lines.append(f"  ratio to bare Zenoh: median {m:.1f}x, p99 {p:.1f}x (target <= 1.5: {met})")
    return lines


RECEIVER = """
import json, sys, time, zenoh
conf = zenoh.Config.from_json5(sys.argv[1])
s = zenoh.open(conf)
got = []
sub = s.declare_subscriber("bare/ping", lambda x: got.append(time.monotonic() - float(x.payload.to_string())))
print("ready", flush=True)
sys.stdin.readline()
print(json.dumps(got), flush=True)
s.close()
"""


def bare_zenoh(certs: Path, rounds: int, rate_hz: float) -> np.ndarray:
    import zenoh

    from orccadd.cellnet.zconfig import to_json5, zenoh_config

    port = free_port()

    def conf(name: str, listen: list[str], connect: list[str]) -> str:
        raw = {
            "name": CELL,
            "robot": name,
            "listen": listen,
            "connect": connect,
            "ca": str(certs / "ca.pem"),
            "certificate": str(certs / f"{name}.pem"),
            "private_key": str(certs / f"{name}.key"),
        }
        return to_json5(zenoh_config(load_cellnet(raw, "<benchmark>", name), daemon=False))

    rx = subprocess.Popen(
        [sys.executable, "-c", RECEIVER, conf("bench-b", [f"tls/127.0.0.1:{port}"], [])],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert rx.stdout is not None and rx.stdin is not None
        rx.stdout.readline()
        s = zenoh.open(zenoh.Config.from_json5(conf("bench-a", [], [f"tls/127.0.0.1:{port}"])))
        pub = s.declare_publisher("bare/ping", express=True)
        time.sleep(1.0)
        for _ in range(rounds):
            pub.put(repr(time.monotonic()))
            time.sleep(1.0 / rate_hz)
        time.sleep(0.5)
        rx.stdin.write("\n")
        rx.stdin.flush()
        got = json.loads(rx.stdout.readline())
        s.close()
    finally:
        rx.kill()
        rx.wait()
    return np.asarray(got) * 1e6


# ---- load ---------------------------------------------------------------------------------------
def wake_p99s(ds: list[DaemonProcess], duration_s: float) -> list[np.ndarray]:
    with contextlib.ExitStack() as stack:
        polls = []
        recs = []
        for d in ds:
            rec, poll = stack.enter_context(recording(stack.enter_context(d.client())))
            recs.append(rec)
            polls.append(poll)
        run_for(duration_s, lambda: [p() for p in polls])
    return [r.resource_ticks(0)[:, T.WAKE_US] for r in recs]


def run_load(certs: Path, duration_s: float) -> list[str]:
    """Without the cell, with it, without it again (this VM's noise drifts within minutes: the
    runs without bracket the one with); each after a warm-up."""
    names = ["bench-a", "bench-b", "bench-c"]
    runs: dict[str, list[np.ndarray]] = {}
    samples = 0
    for label in ("without", "with", "without again"):
        with daemons(names, certs, cell=label == "with") as ds:
            if label != "with":
                time.sleep(WARM_UP_S)
                runs[label] = wake_p99s(ds, duration_s)
                continue
            console = console_for(certs, endpoints_of(ds))
            counted = [0]
            sub = console.session.declare_subscriber(
                f"orccadd/{CELL}/**", lambda _, c=counted: c.__setitem__(0, c[0] + 1)
            )
            time.sleep(WARM_UP_S)
            runs[label] = wake_p99s(ds, duration_s)
            samples = counted[0]
            sub.undeclare()  # type: ignore[no-untyped-call]
            console.close()
    lines = [
        f"load: three daemons, {duration_s:g} s per run; with the cell the console got {samples} samples"
    ]
    worst = spread = 0.0
    for i, name in enumerate(names):
        p0, p1 = (float(np.percentile(runs[k][i], 99)) for k in ("without", "without again"))
        for label in ("without", "with", "without again"):
            w = runs[label][i]
            lines.append(f"  {name} {label + ' the cell:':27s} wake-up {figures(w, 'µs')}")
        ratio = float(np.percentile(runs["with"][i], 99)) / ((p0 + p1) / 2)
        worst, spread = max(worst, ratio), max(spread, max(p0, p1) / min(p0, p1))
        lines.append(f"  {name}: p99 with the cell / the mean p99 of the runs without: {ratio:.2f}")
    verdict = "met" if worst <= 1.10 else "NOT met"
    lines.append(
        f"  worst ratio {worst:.2f} (target <= 1.10: {verdict}); the two runs without the cell differ "
        f"by up to {100 * (spread - 1):.0f} % between themselves"
    )
    return lines


# ---- scale --------------------------------------------------------------------------------------
def run_scale(certs: Path, sizes: list[int], refreshes: int) -> list[str]:
    lines = ["scale: the console's refresh (every daemon's status) and a command's round trip (describe)"]
    for n in sizes:
        names = [f"bench-{i}" for i in range(n)]
        with daemons(names, certs) as ds:
            console = console_for(certs, endpoints_of(ds))
            seen = len(console.robots())
            refresh, trip = [], []
            unanswered = 0
            for i in range(refreshes):
                t0 = time.monotonic()
                replies = console.status_all()
                refresh.append((time.monotonic() - t0) * 1e3)
                unanswered += sum(not r.get("ok") for r in replies.values()) + n - len(replies)
                t0 = time.monotonic()
                r = console.request(names[i % n], "describe")
                trip.append((time.monotonic() - t0) * 1e3)
                unanswered += not r.get("ok")
            overruns = sum(int(d.status()["overruns"]) for d in ds)
            console.close()
        lines.append(f"  {n} daemon(s) ({seen} seen): refresh {figures(refresh, 'ms', 2)}")
        lines.append(f"  {n} daemon(s): command round trip {figures(trip, 'ms', 2)}")
        lines.append(f"  {n} daemon(s): {unanswered} requests unanswered; the loops' overruns {overruns}")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else "")
    ap.add_argument("--rounds", type=int, default=300, help="latency: signals sent")
    ap.add_argument("--rate-hz", type=float, default=20.0, help="latency: signals per second")
    ap.add_argument("--duration-s", type=float, default=30.0, help="load: seconds recorded each way")
    ap.add_argument("--sizes", default="1,3,8", help="scale: cells of so many daemons")
    ap.add_argument("--refreshes", type=int, default=50, help="scale: console refreshes per size")
    ap.add_argument("--parts", default="latency,load,scale")
    a = ap.parse_args()
    parts = a.parts.split(",")
    certs = make_cell_certs(
        Path(tempfile.mkdtemp(prefix="orccadd-cell-certs-")), ["console", *[f"bench-{x}" for x in "abc"]]
    )
    if "scale" in parts:
        make_cell_certs(certs, [f"bench-{i}" for i in range(max(int(s) for s in a.sizes.split(",")))])
    out: list[str] = []
    if "latency" in parts:
        out += run_latency(certs, a.rounds, a.rate_hz)
    if "load" in parts:
        out += run_load(certs, a.duration_s)
    if "scale" in parts:
        out += run_scale(certs, [int(s) for s in a.sizes.split(",")], a.refreshes)
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
