"""Is `abort` (and `stop`) acted on within 2 control periods of its arrival, under client load?

Runs `orccadd` on sim-ur5e (500 Hz) with benchmarks/missions/isolation.mission (the arm shuttles:
Ruckig + computed torque). Load, in processes of their own, all through the real socket:

- `--busy N` control clients (default 12) each sending requests the real-time process answers
  (`describe`, `params`, `tune`, a `send` it refuses), back to back, as fast as it replies;
- `--big N` clients (default 2) sending requests of ~900 kB (refused by the command daemon);
- 10 `monitor` streams at 100 Hz.

Each round: start the mission, let it move, send `abort` (or, with `--command stop`, the
mission's graceful Stop) from a client of its own, alternately through the urgent socket (what
`orccadctl abort` uses: the real-time process reads it) and through the main socket (the command
daemon's queue), and take the first tick whose record shows
the safe stop (status `stopping`/`stopped`; for stop, the task switch or end). The latency is
that tick's release time minus the moment the request was written to the socket (both
CLOCK_MONOTONIC): what an operator's abort waits for, the command daemon included. Then reset
and the next round. Prints median/p99/max in µs and in periods; target: max ≤ 2 periods.
Usage: `python benchmarks/abort_latency.py [--rounds 40] [--busy 12] [--command abort|stop]`.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import socket
import subprocess
import sys
import time
from typing import Any

import numpy as np
from harness import ROOT, figures, running_daemon

from orccadd.ctl.client import Client, ClientError
from orccadd.types import Status
from orccadd.wire.schema import H, OperatorAction, R, T, Trace
from orccadd.wire.socketdir import urgent_socket_path
from orccadd.wire.telemetry import RingReader, TelemetryBlock

MISSION = ROOT / "benchmarks/missions/isolation.mission"
STOPPED = int(Status.STOPPING | Status.STOPPED)
MONITORS = 10


def busy_client(sock: str, k: int, stop: Any) -> None:
    """Requests that reach the real-time process, back to back."""
    calls: list[tuple[str, dict[str, Any]]] = [
        ("describe", {}),
        ("params", {}),
        ("tune", {"path": "Out.traj.speed_scale", "value": 0.8}),
        ("send", {"input": "NoSuchInput"}),
    ]
    with Client(sock, timeout_s=60) as c:
        i = k
        while not stop.is_set():
            cmd, args = calls[i % len(calls)]
            try:
                c.reply(cmd, **args)
            except (ClientError, OSError):
                time.sleep(0.01)
            i += 1


def big_client(sock: str, stop: Any) -> None:
    """~900 kB requests, one after the other (the command daemon refuses them)."""
    line = b'{"id": 1, "cmd": "tune", "args": {"path": "' + b"x" * 900_000 + b'", "value": 1}}\n'
    while not stop.is_set():
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
                s.settimeout(10)
                s.connect(sock)
                s.sendall(line)
                s.recv(4096)
        except OSError:
            time.sleep(0.01)


def acted_on(tel: TelemetryBlock, reader: RingReader, sent_s: float, cmd: str, task0: int) -> float:
    """Release time (s) of the first tick after `sent_s` that shows the command's effect."""
    end = time.monotonic() + 5.0
    while time.monotonic() < end:
        for rec in reader.poll():
            if rec[T.T_S] < sent_s - 0.5 * float(tel.header[H.PERIOD_S]):
                continue
            if cmd == "abort" and int(rec[T.STATUS]) & STOPPED:
                return float(rec[T.T_S])
            if cmd == "stop" and int(rec[T.TASK]) != task0:
                return float(rec[T.T_S])
        time.sleep(0.002)
    raise RuntimeError(f"{cmd}: no effect seen within 5 s")


def handled_at(tel: TelemetryBlock, trace: RingReader, cmd: str) -> float:
    """Loop-clock time (s) at which the real-time process handled the command (its trace record)."""
    action = OperatorAction.ABORT if cmd == "abort" else OperatorAction.STOP
    for rec in trace.poll():
        if int(rec[R.KIND]) == Trace.COMMAND and int(rec[R.CODE]) == action:
            return float(rec[R.T_S])
    return float("nan")


def one_round(
    c: Client, tel: TelemetryBlock, block: TelemetryBlock, cmd: str, sender: Client
) -> tuple[float, float]:
    """(written -> handled by the real-time process, written -> first tick acted on), seconds;
    `tel` the arm's block (its ticks), `block` the daemon's (its trace)."""
    c.call("start")
    time.sleep(0.6 + np.random.default_rng().uniform(0, 0.4))  # moving, at a random phase
    reader = RingReader(tel.ticks, tel.header, H.TICK_HEAD, from_now=True)
    trace = RingReader(block.trace, block.header, H.TRACE_HEAD, from_now=True)
    task0 = int(tel.ticks[(int(tel.header[H.TICK_HEAD]) - 1) % len(tel.ticks), T.TASK])
    sent = time.monotonic()
    sender.call(cmd)
    latency = acted_on(tel, reader, sent, cmd, task0) - sent
    handled = handled_at(tel, trace, cmd) - sent
    at_rest = cmd == "stop" or "stopped" in c.call("status").get("resource_status", [])
    wait_state(c, lambda s: s["state"] == "ready" and (at_rest or "stopped" in s.get("resource_status", [])))
    s = c.call("status")
    if s["faulted"] or "stopped" in s.get("resource_status", []):
        c.call("reset")
        wait_state(c, lambda s: not s["faulted"] and "stopped" not in s.get("resource_status", []))
    return handled, latency


def wait_state(c: Client, pred: Any, timeout_s: float = 30.0) -> None:
    end = time.monotonic() + timeout_s
    while not pred(c.call("status")):
        if time.monotonic() > end:
            raise RuntimeError(f"timed out; status {c.call('status')}")
        time.sleep(0.05)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=40)
    ap.add_argument("--busy", type=int, default=12)
    ap.add_argument("--big", type=int, default=2)
    ap.add_argument("--command", choices=("abort", "stop"), default="abort")
    args = ap.parse_args()
    ctx = mp.get_context("fork")
    stop = ctx.Event()
    latencies: dict[str, list[tuple[float, float]]] = {"urgent": [], "main": []}
    with running_daemon() as d, Client(d.socket, timeout_s=120) as c:
        c.call("load", path=str(MISSION))
        desc = c.call("describe")
        tel = TelemetryBlock.attach(str(desc["telemetry"]))
        block = TelemetryBlock.attach(str(desc["daemon_telemetry"]))
        period_s = float(tel.header[H.PERIOD_S])
        env = {**os.environ, "ORCCADD_SOCKET": d.socket}
        mon = [sys.executable, "-m", "orccadd.cli", "monitor", "q", "dq", "--rate", "100", "--json"]
        monitors = [
            subprocess.Popen(mon, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            for _ in range(MONITORS)
        ]
        procs = [ctx.Process(target=busy_client, args=(d.socket, k, stop)) for k in range(args.busy)]
        procs += [ctx.Process(target=big_client, args=(d.socket, stop)) for _ in range(args.big)]
        for p in procs:
            p.start()
        try:
            time.sleep(1.0)
            with Client(urgent_socket_path(d.socket)) as urgent:
                for k in range(args.rounds):  # both paths in turn, under the same load
                    path = "urgent" if k % 2 == 0 else "main"
                    sender = urgent if path == "urgent" else c
                    latencies[path].append(one_round(c, tel, block, args.command, sender))
            ticks = int(tel.header[H.TICKS])
            overruns = int(tel.header[H.OVERRUNS])
        finally:
            stop.set()
            for p in procs:
                p.join(timeout=10)
                if p.is_alive():
                    p.kill()
            for m in monitors:
                m.terminate()
                m.wait(timeout=10)
            tel.close()
    print(
        f"abort_latency: sim-ur5e, {1 / period_s:g} Hz, mission Shuttle; `{args.command}` x {args.rounds} "
        f"under {args.busy} busy control clients, {args.big} clients of 900 kB requests, {MONITORS} monitors"
    )
    worst = 0.0
    for path, label in (
        ("urgent", "urgent socket (orccadctl abort/stop)"),
        ("main", "main socket (command daemon)"),
    ):
        handled, lat = (np.array(x) for x in zip(*latencies[path], strict=True))
        print(f"  {label}:")
        print(f"    request written -> handled (rt process) {figures(handled * 1e6, 'µs', 0)}")
        print(f"    request written -> first tick acted on  {figures(lat * 1e6, 'µs', 0)}")
        print(f"    in control periods                      {figures(lat / period_s, 'periods', 2)}")
        if path == "urgent":
            worst = float(lat.max() / period_s)
    print(f"  loop: {ticks} ticks, {overruns} overruns")
    print(f"  target (urgent socket): max ≤ 2 periods -> {'met' if worst <= 2 else 'NOT met'} ({worst:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
