"""The joint states a daemon publishes to its cell: samples a subscriber receives per second for
each `joints_hz` asked, over loopback TLS (a simulated UR5e at 500 Hz, a console subscribed to
`orccadd/bench/<robot>/joints`).

Printed per rate asked: the samples received in each whole second of the run (median, min, max)
and the mean over the run.

Usage: `python benchmarks/cell_joints.py [--rates-hz 100,250,500] [--duration-s 10]`.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from cell_zenoh import WARM_UP_S, console_for, daemons, endpoints_of

from orccadd.cellnet.certs import make_cell_certs


def samples_per_s(joints_hz: float, certs: Path, duration_s: float) -> np.ndarray:
    """Samples received in each whole second of `duration_s`, one daemon at `joints_hz`."""
    with daemons(["bench-a"], certs, cell_lines=f"joints_hz = {joints_hz:g}\n") as ds:
        time.sleep(WARM_UP_S)
        stamps: list[float] = []
        lock = threading.Lock()

        def on_sample(_: object) -> None:  # Zenoh's thread
            with lock:
                stamps.append(time.monotonic())

        with console_for(certs, endpoints_of(ds)) as con:
            sub = con.session.declare_subscriber("orccadd/bench/bench-a/joints", on_sample)
            t0 = time.monotonic() + 1.0  # whole seconds after the first one
            time.sleep(duration_s + 1.0)
            sub.undeclare()
        with lock:
            t = np.asarray(stamps)
        seconds = int(duration_s)
        return np.histogram(t, bins=seconds, range=(t0, t0 + seconds))[0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else "")
    ap.add_argument("--rates-hz", default="100,250,500", help="joints_hz asked, one daemon each")
    ap.add_argument("--duration-s", type=float, default=10.0, help="seconds counted per rate")
    args = ap.parse_args()
    certs = make_cell_certs(Path(tempfile.mkdtemp(prefix="orccadd-certs-")), ["bench-a", "console"])
    for rate in (float(r) for r in args.rates_hz.split(",")):
        per_s = samples_per_s(rate, certs, args.duration_s)
        print(
            f"joints_hz {rate:g}: received per second median {np.median(per_s):.0f}, "
            f"min {per_s.min()}, max {per_s.max()}, mean {per_s.mean():.1f} ({len(per_s)} s)",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
