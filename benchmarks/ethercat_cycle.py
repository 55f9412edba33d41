"""An EtherCAT line of six CiA 402 drives at 1 kHz and 2 kHz against the slave simulator: frames
lost, working-counter errors, skipped periods against cyclictest's misses in the same run.

For each rate: the slave simulator (`python -m orccadd.ecatsim`, configs/robots/ethercat-6axis-sim
at that period, SCHED_FIFO 70, its own veth link and namespace), the `ethercat402` resource on
the master's end (SOEM through pysoem; distributed clocks: SYNC0 at the period, the ticks
released at the reference clock's period starts by `wait_for_cycle`), holding the arm in CSP at
SCHED_FIFO 80 with memory locked like the daemon's control thread, for `--duration-s`. Then
`cyclictest` at the same period and priority, half of `--duration-s` just before the loop and
half just after, the simulator up and idle (this VM's noise drifts within minutes).

Definitions:
- a *skipped period*: a period start on the reference clock that released no tick (a tick that
  ended after the next start: `wait_for_cycle` then waits for the one after), counted from the
  release times;
- a cyclictest *miss*: a wake-up later than one period after its release; target: skipped
  periods <= cyclictest's misses;
- a *lost frame*: a frame that did not come back within the receive timeout (a third of the
  period); a *working-counter error*: one that came back short of the expected count;
- the simulator's own figures: frames it answered, and the longest gap of its loop.

Prints median / p99 / max of the release period, the wake-up latency (release -> the control
thread running) and read() + write(), per rate. Usage: `python benchmarks/ethercat_cycle.py
[--rates 1000,2000] [--duration-s 600]` (root: SCHED_FIFO, and the simulator's namespace).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from harness import ROOT, cyclictest, figures

from orccadd.ecatsim.process import EcatSimProcess
from orccadd.physres.ethercat402 import Ethercat402Arm
from orccadd.robot import create_resource, load_robot_config
from orccadd.runtime import enter_realtime, leave_realtime
from orccadd.types import CommandMode

CONFIG = ROOT / "configs/robots/ethercat-6axis-sim.toml"
PRIORITY = 80
SIM_PRIORITY = 70


def config_at(period_s: float, tmp: Path) -> Path:
    text = CONFIG.read_text().replace('"../', f'"{CONFIG.parent.parent}/')
    text = text.replace("control_period_s = 0.001", f"control_period_s = {period_s:g}")
    path = tmp / CONFIG.name
    path.write_text(text)
    return path


def run_rate(rate_hz: float, duration_s: float) -> None:
    period_s = 1.0 / rate_hz
    period_ns = round(period_s * 1e9)
    with tempfile.TemporaryDirectory() as tmp:
        config = config_at(period_s, Path(tmp))
        with EcatSimProcess(config, "--priority", str(SIM_PRIORITY)) as sim:
            before = cyclictest(period_s, duration_s / 2, PRIORITY)
            # real time first (mlockall takes a while): the keeper thread cycles the line until
            # the loop's first tick, and nothing may stall between them for the SM watchdog's time
            rt = enter_realtime(PRIORITY, cpus=None)
            arm = create_resource(load_robot_config(config))
            assert isinstance(arm, Ethercat402Arm)
            arm.configure()
            arm.activate(CommandMode.POSITION)
            m = arm.master
            n = int(duration_s * rate_hz)
            rec = np.zeros((n, 4), dtype=np.int64)  # release, woke, read done, write done (ns)
            frames0, lost0, wkc0 = m.frames, m.frames_lost, m.wkc_errors
            sim0 = sim.status()
            hold: np.ndarray | None = None
            comm_lost = k = 0
            try:
                while k < n:
                    release = arm.wait_for_cycle(10 * period_s)
                    woke = time.monotonic_ns()
                    if release < 0:
                        release = woke
                    st = arm.read(release * 1e-9)
                    t_read = time.monotonic_ns()
                    if hold is None:
                        hold = st.q_rad.copy()  # where the first tick finds the arm
                    arm.write(release * 1e-9, hold)
                    rec[k] = (release, woke, t_read, time.monotonic_ns())
                    comm_lost += bool(st.status & 0x08)
                    k += 1
            finally:
                leave_realtime(rt)
            frames, lost, wkc = m.frames - frames0, m.frames_lost - lost0, m.wkc_errors - wkc0
            sim1 = sim.status()
            fault = arm.fault_message
            arm.shutdown()
            after = cyclictest(period_s, duration_s / 2, PRIORITY)
    releases = rec[:, 0]
    steps = np.diff(releases)
    skipped = int(np.sum(np.maximum(0, np.round(steps / period_ns) - 1)))
    base = (
        np.concatenate([x for x in (before, after) if x is not None])
        if (before is not None or after is not None)
        else None
    )
    misses = int(np.sum(base >= period_s * 1e6)) if base is not None else -1
    print(
        f"  {rate_hz:g} Hz, {duration_s:g} s, {n} ticks (SCHED_FIFO {rt.sched_fifo_priority}, memory locked)"
    )
    print(f"    frames {frames}: lost {lost}, working-counter errors {wkc}; ticks with COMM_LOST {comm_lost}")
    wakeups = len(base) if base is not None else 0
    print(f"    skipped periods {skipped}   cyclictest misses {misses} (in {wakeups} wake-ups)")
    print(f"    release period      {figures(steps / 1e3, 'µs')}")
    print(f"    wake-up latency     {figures((rec[:, 1] - rec[:, 0]) / 1e3, 'µs')}")
    if base is not None:
        print(f"    cyclictest latency  {figures(base, 'µs')}")
    print(f"    read()              {figures((rec[:, 2] - rec[:, 1]) / 1e3, 'µs')}")
    print(f"    write()             {figures((rec[:, 3] - rec[:, 2]) / 1e3, 'µs')}")
    print(
        f"    simulator: {sim1['frames'] - sim0['frames']} frames answered, longest loop gap "
        f"{sim1['longest_loop_gap_ms']:.2f} ms; AL states {sorted(set(sim1['al_states']))}"
    )
    if fault:
        print(f"    fault: {fault}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="1000,2000", help="comma-separated rates (Hz)")
    ap.add_argument("--duration-s", type=float, default=600.0)
    args = ap.parse_args()
    if os.geteuid() != 0:
        print("root needed: SCHED_FIFO and the simulator's network namespace")
        return 1
    print(f"EtherCAT cycle: six CiA 402 drives on the slave simulator ({CONFIG.name}), CSP hold")
    for rate in (float(r) for r in args.rates.split(",")):
        run_rate(rate, args.duration_s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
