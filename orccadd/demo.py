"""`make demo`: orccadd on the simulated UR5e, driven through orccadctl's protocol like an operator.

Starts the daemon (real-time process, command daemon, plant process) on a private socket, loads
and verifies configs/missions/demo.mission (three motions and a type 2 recovery), records a
full-rate CSV log, starts the mission and follows its reactive trace live, tunes a gain mid-run,
prints a summary when the mission ends, writes a plot PNG and stops the daemon with SIGTERM
(safe stop first). A mission stopped by a type 3 exception (e.g. the shared machine stalled the
loop) is reported, reset and run once more, as an operator would.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from orccadd.ctl.client import Client, ClientError
from orccadd.ctl.format import format_trace
from orccadd.ctl.online import copy_to, format_status
from orccadd.launch import DaemonError, DaemonProcess
from orccadd.offline.plot import plot_csv

ROOT = Path(__file__).resolve().parent.parent


def follow(c: Client, seen: int, tuned: list[bool]) -> tuple[int, dict[str, Any]]:
    """Print new trace entries; tune once while Reach runs. Returns (last seq, status)."""
    for e in c.call("events", last=100)["events"]:
        if e["seq"] > seen:
            print("  " + format_trace(e), flush=True)
            seen = e["seq"]
    s: dict[str, Any] = c.call("status")
    if not tuned[0] and s.get("active_task") == "Reach":
        r = c.call("tune", path="Approach.traj.speed_scale", value=0.6)
        print(
            f"  tune Approach.traj.speed_scale: {r['previous']} -> {r['value']} (applied at a tick boundary)"
        )
        tuned[0] = True
    return seen, s


def run_mission(c: Client, seen: int, tuned: list[bool]) -> tuple[int, dict[str, Any]]:
    c.call("start")
    t0 = time.monotonic()
    while True:
        time.sleep(0.1)
        seen, s = follow(c, seen, tuned)
        if s["state"] == "ready" or (s["faulted"] and s["state"] == "running"):
            break
        if time.monotonic() - t0 > 60:
            c.call("abort")
            raise SystemExit("the mission did not end within 60 s")
    print(f"mission ended: {s['result']} in {time.monotonic() - t0:.1f} s", flush=True)
    return seen, s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--robot", default=str(ROOT / "configs/robots/sim-ur5e.toml"))
    ap.add_argument("--mission", default=str(ROOT / "configs/missions/demo.mission"))
    ap.add_argument("--out", default=str(ROOT / "demo-out"), help="folder for the log and the plot")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix="orccadd-demo-")
    sock = f"{tmp}/orccadd.sock"
    daemon_log = out / "orccadd.log"
    print(f"$ orccadd --config {args.robot} --socket {sock}", flush=True)
    try:
        daemon = DaemonProcess(args.robot, sock, daemon_log)
    except DaemonError as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise SystemExit(str(e)) from None
    code = 1
    try:
        with daemon.client(timeout_s=120) as c:
            print(format_status(c.call("status")))
            print(f"$ orccadctl load {args.mission}")
            print(c.call("load", path=args.mission)["report"])
            csv = out / "demo.csv"
            name = f"demo-{time.strftime('%Y%m%d-%H%M%S')}.csv"
            signals = ["q", "dq", "tau", "cmd", "wake_us", "compute_us"]
            print(f"$ orccadctl log start {' '.join(signals)} --name {name}")
            c.call("log", action="start", signals=signals, name=name)
            tuned = [False]
            seen, s = run_mission(c, 0, tuned)
            if s["result"] != "success":
                print(f"type 3 exception ({s['result']}): acknowledge (Stop), reset, run again", flush=True)
                if s["state"] == "running":
                    c.call("stop")
                time.sleep(1.0)
                while c.call("status")["faulted"]:
                    try:
                        c.call("reset")
                    except ClientError:
                        time.sleep(0.5)
                seen, s = run_mission(c, seen, tuned)
            time.sleep(0.3)
            print(f"$ orccadctl log stop -o {csv}")
            info = c.call("log", action="stop")
            copy_to(Path(info["file"]), csv)  # the daemon writes into its own log directory
            mcaps = [out / f"demo{'' if i == 0 else f'-{i + 1}'}.mcap" for i in range(len(info["mcap"]))]
            for part, dest in zip(info["mcap"], mcaps, strict=True):  # the same log for Foxglove
                copy_to(Path(part), dest)
            print(f"log: {csv}: {info['rows']} rows at full rate, {info['lost']} lost")
            print(f"log: {', '.join(str(m) for m in mcaps)} (MCAP: Foxglove, the mcap tools)")
            print(format_status(c.call("status")))
            png = out / "demo.png"
            print(plot_csv(csv, png, ["q", "tau", "wake_us"]))
            code = 0 if s["result"] == "success" else 1
    finally:
        if daemon.proc.poll() is None:
            rc = daemon.stop()
            print(f"orccadd stopped (exit {rc}): {daemon_log.read_text().strip().splitlines()[-1]}")
            code = code or (1 if rc else 0)
        shutil.rmtree(tmp, ignore_errors=True)  # its socket and the daemon's log directory
    return code


if __name__ == "__main__":
    raise SystemExit(main())
