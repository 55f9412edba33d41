"""How late the kernel hands a serial port's received bytes on (`flush_to_ldisc`), and what ran
instead: the check for a robot PC with a DYNAMIXEL chain (docs/install.md, step 7).

A tty's received bytes (a USB adapter's, as a pseudo-terminal's) go from the driver's flip
buffer to the line discipline, where `read`/`select` see them, in a kernel worker: the work item
`flush_to_ldisc`, queued on the `events_unbound` workqueue and run by a `kworker/uN:M` thread,
time-shared at nice 0. Until it runs, the reply is in the machine but the daemon does not see it.

This records, with the kernel's tracing (root; tracefs at /sys/kernel/tracing), every
`flush_to_ldisc` queued during `--seconds` and when a kworker started it: the wait's median,
p99 and max, how many waited over `--threshold-ms`, and for each of those what ran on every
CPU when it was queued (task-pid and the kernel's priority: 0-98 real time, 99 - rtprio, so
SCHED_FIFO 80 is 19; 100-139 time-shared, 120 + nice, so nice 0 is 120 and nice -10 is 110).
Run it while orccadd drives the chain (a mission running, a task starting):

    sudo /opt/orccadd/venv/bin/python tty_kworker.py --seconds 10

It changes nothing but the kernel's trace buffer (events, clock, size), which it empties and
switches off at the end: do not run it while someone else traces.
"""

from __future__ import annotations

import argparse
import collections
import re
import sys
import time
from pathlib import Path

TRACING = Path("/sys/kernel/tracing")
EVENTS = ("workqueue:workqueue_queue_work", "workqueue:workqueue_execute_start", "sched:sched_switch")
LINE = re.compile(r"^\s*(.+?)-(\d+)\s+\[(\d+)\]\s+\S+\s+([\d.]+):\s+(\w+):\s*(.*)$")
SWITCH = re.compile(r"next_comm=(.*?) next_pid=(\d+) next_prio=(\d+)")


def write(name: str, text: str) -> None:
    (TRACING / name).write_text(text)


def record(seconds: float, buffer_kb: int) -> list[str]:
    write("tracing_on", "0")
    write("trace", "")
    write("trace_clock", "mono")
    write("buffer_size_kb", str(buffer_kb))
    write("set_event", "\n".join(EVENTS) + "\n")
    write("tracing_on", "1")
    try:
        time.sleep(seconds)
    finally:
        write("tracing_on", "0")
        text = (TRACING / "trace").read_text()
        write("set_event", "")
        write("trace", "")
    return text.splitlines()


def analyse(lines: list[str], threshold_s: float, show: int) -> int:
    on_cpu: dict[int, str] = {}  # what runs on each CPU now
    queued: dict[str, tuple[float, str, dict[int, str]]] = {}
    waits: list[float] = []
    slow: list[tuple[float, float, str, str, dict[int, str]]] = []
    workers: collections.Counter[str] = collections.Counter()
    t_first = None
    for line in lines:
        m = LINE.match(line)
        if not m:
            continue
        comm, pid, cpu, t, ev, rest = (
            m.group(1).strip(),
            m.group(2),
            int(m.group(3)),
            float(m.group(4)),
            m.group(5),
            m.group(6),
        )
        t_first = t if t_first is None else t_first
        if ev == "sched_switch":
            s = SWITCH.search(rest)
            if s:
                on_cpu[cpu] = f"{s.group(1)}-{s.group(2)} prio {s.group(3)}"
        elif "flush_to_ldisc" not in rest:
            continue
        elif ev == "workqueue_queue_work":
            w = re.search(r"struct=(\S+)", rest)
            if w and w.group(1) not in queued:
                queued[w.group(1)] = (t, f"{comm}-{pid}", dict(on_cpu))
        elif ev == "workqueue_execute_start":
            w = re.search(r"struct (\S+):", rest)
            if w and w.group(1) in queued:
                tq, by, cpus = queued.pop(w.group(1))
                waits.append(t - tq)
                workers[re.sub(r":\d+$", "", comm)] += 1
                if t - tq > threshold_s:
                    slow.append((tq, t - tq, by, f"{comm}-{pid} on CPU {cpu}", cpus))
    if not waits:
        print("no flush_to_ldisc in the trace: is a serial port in use (orccadd running a chain)?")
        return 1
    waits.sort()
    n = len(waits)
    print(
        f"flush_to_ldisc waits (queued -> a kworker starts it): n={n}, median {waits[n // 2] * 1e3:.3f} ms, "
        f"p99 {waits[min(n - 1, int(0.99 * n))] * 1e3:.3f} ms, max {waits[-1] * 1e3:.3f} ms; "
        f"over {threshold_s * 1e3:g} ms: {len(slow)}"
    )
    print("run by:", ", ".join(f"{k} ({v})" for k, v in workers.most_common(4)))
    for tq, wait, by, worker, cpus in slow[:show]:
        running = "; ".join(f"CPU {c}: {who}" for c, who in sorted(cpus.items()))
        print(
            f"  +{tq - (t_first or tq):.3f} s: waited {wait * 1e3:.2f} ms (queued by {by}, run by {worker}); "
            f"running when queued: {running}"
        )
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="how long to record")
    ap.add_argument("--threshold-ms", type=float, default=1.0, help="waits longer than this are listed")
    ap.add_argument("--show", type=int, default=20, help="at most this many listed")
    ap.add_argument("--buffer-kb", type=int, default=30000, help="trace buffer per CPU")
    args = ap.parse_args()
    if not (TRACING / "trace").exists():
        print(f"{TRACING}: no tracefs (mount -t tracefs nodev {TRACING}; needs root)", file=sys.stderr)
        return 2
    try:
        lines = record(args.seconds, args.buffer_kb)
    except PermissionError as e:
        print(f"{e}: run as root", file=sys.stderr)
        return 2
    return analyse(lines, args.threshold_ms * 1e-3, args.show)


if __name__ == "__main__":
    raise SystemExit(main())
