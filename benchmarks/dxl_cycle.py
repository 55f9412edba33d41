"""Six DYNAMIXEL servos (dxl-6axis-sim, the simulated chain on a pseudo-terminal) at 1, 2, 3 and
4 Mbit/s: the `dynamixel` resource's bus cycle against the wire time, and the loop rate it holds.

For each baud rate, against `python -m orccadd.dxlsim` (which delays every status packet to the
wire time of the bytes at that rate, see `orccadd.dxlsim.link`), with the arm held in position
mode and this process at SCHED_FIFO 80 where permitted:

- the wire time of one cycle from the packet lengths (`drivers.dynamixel.wire`: one Fast Sync
  Read of current, velocity and position + one Sync Write of Goal Position, 10 bits a byte, the
  servos' return delay): what `describe()` declares;
- the measured cycle, back to back for `--cycle-s`: the chain's sync read + sync write alone,
  and the resource's `read()` + `write()` (units, limits and checks included): median, p99, max,
  and the chain's median over the wire time;
- the highest loop rate that holds for `--seconds` with no timeout, no damaged reply and no
  skipped period: rates tried from the fastest the cycle's p99 allows, down a ladder, each run
  stopped at its first failure.

The simulated chain holds each reply's tail short of a USB packet (62 bytes) for
`--latency-timer-ms`, as an FTDI adapter does (default 1 ms, as packaging/udev sets it; the
adapter's own default is 16 ms), and the backend writes `--return-delay-us` (default 0; the
servos' factory value is 500 µs): run once with `--latency-timer-ms 16 --return-delay-us 500`
to see what the settings are worth.

Targets: measured cycle ≤ 1.3 × the wire time; 6 servos at 4 Mbit/s ≥ 500 Hz. Usage:
`python benchmarks/dxl_cycle.py [--seconds 60] [--bauds 1000000,2000000,3000000,4000000]
[--latency-timer-ms 1] [--return-delay-us 0]`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from harness import ROOT, figures

from orccadd.drivers.dynamixel import table as T
from orccadd.dxlsim.process import DxlSimProcess
from orccadd.errors import ConfigError, ResourceError
from orccadd.physres.dynamixel import DynamixelArm
from orccadd.robot import create_resource, load_robot_config
from orccadd.runtime import WallClock, enter_realtime, leave_realtime
from orccadd.types import CommandMode

SIM = ROOT / "configs/robots/dxl-6axis-sim.toml"
LADDER_HZ = (2000, 1600, 1250, 1000, 800, 625, 500, 400, 250, 200, 100)
CYCLE_TARGET = 1.3
RATE_TARGET_HZ = 500.0


@dataclass
class RateRun:
    rate_hz: float
    ticks: int = 0
    timeouts: int = 0
    damaged: int = 0
    skipped: int = 0  # periods the loop missed (a late tick)
    longest_failed_run: int = 0  # failed reads in a row (the resource's CommLost counts these)
    first_failure: str = ""

    @property
    def held(self) -> bool:
        return self.ticks > 0 and not (self.timeouts or self.damaged or self.skipped)

    def describe(self) -> str:
        return (
            f"{self.ticks} cycles: {self.timeouts} timeouts, {self.damaged} damaged replies, "
            f"{self.skipped} skipped periods, longest run of failed reads {self.longest_failed_run}"
        )


def met(ok: bool) -> str:
    return "met" if ok else "NOT met"


RETURN_DELAY_US = 0  # set by --return-delay-us (main)


def config_text(port: Path, baud: int, period_s: float, read_timeout_s: float) -> str:
    text = SIM.read_text().replace('"../urdf/', f'"{ROOT}/configs/urdf/')
    text = text.replace('port = "/tmp/orccadd-dxl-6axis"', f'port = "{port}"')
    text = text.replace(
        "baud_rate = 4_000_000",
        f"baud_rate = {baud}\nread_timeout_s = {read_timeout_s:g}\nreturn_delay_us = {RETURN_DELAY_US}",
    )
    return text.replace("control_period_s = 0.005", f"control_period_s = {period_s:g}")


def open_arm(config: Path) -> DynamixelArm:
    arm = create_resource(load_robot_config(config))
    assert isinstance(arm, DynamixelArm)
    arm.configure()
    arm.activate(CommandMode.POSITION)
    return arm


def measure_cycles(arm: DynamixelArm, seconds: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Back-to-back cycles: the chain's (read + write) and the resource's, in ms; failed reads."""
    ch = arm.chain
    hold = list(ch.present_position)
    q = arm.read(time.monotonic()).q_rad.copy()
    chain_ms: list[float] = []
    resource_ms: list[float] = []
    failed0 = ch.timeouts + ch.crc_errors
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        t0 = time.perf_counter()
        ch.read_cycle()
        ch.write_goals(T.GOAL_POSITION, hold)
        t1 = time.perf_counter()
        now = time.monotonic()
        arm.read(now)
        arm.write(now, q)
        t2 = time.perf_counter()
        chain_ms.append((t1 - t0) * 1e3)
        resource_ms.append((t2 - t1) * 1e3)
    return np.array(chain_ms), np.array(resource_ms), ch.timeouts + ch.crc_errors - failed0


def hold_rate(arm: DynamixelArm, rate_hz: float, seconds: float, stop_at_first: bool) -> RateRun:
    """Read + write on absolute deadlines at `rate_hz` for `seconds` (or until the first failure)."""
    ch, clock = arm.chain, WallClock()
    period_ns = int(1e9 / rate_hz)
    q = arm.read(time.monotonic()).q_rad.copy()
    run = RateRun(rate_hz)
    t0, c0 = ch.timeouts, ch.crc_errors
    nxt = time.monotonic_ns() + period_ns
    for _ in range(int(seconds * rate_hz)):
        clock.sleep_until_ns(nxt)
        arm.read(nxt * 1e-9)
        arm.write(nxt * 1e-9, q)
        run.ticks += 1
        run.longest_failed_run = max(run.longest_failed_run, ch.in_a_row)
        nxt += period_ns
        late = time.monotonic_ns() > nxt
        if late:
            run.skipped += 1
            while time.monotonic_ns() > nxt:
                nxt += period_ns
        failed = ch.timeouts != t0 + run.timeouts or ch.crc_errors != c0 + run.damaged
        if failed or late:
            run.timeouts, run.damaged = ch.timeouts - t0, ch.crc_errors - c0
            if not run.first_failure:
                what = (
                    "a timeout" if failed and run.timeouts else "a damaged reply" if failed else "a late tick"
                )
                run.first_failure = f"{what} after {run.ticks / rate_hz:.1f} s"
            if stop_at_first:
                break
    return run


def servo_priority(sim: DxlSimProcess, priority: int) -> None:
    """The servos are hardware on a robot: their timing must not depend on the host's load. The
    simulator sleeps in `select` between packets, so SCHED_FIFO costs the host nothing."""
    if priority:
        try:
            os.sched_setscheduler(sim.proc.pid, os.SCHED_FIFO, os.sched_param(priority))
        except PermissionError:
            print("    (not root: the simulator runs at normal priority)")


def run_baud(baud: int, args: argparse.Namespace, tmp: Path) -> tuple[float, float, float]:
    """(wire ms, measured chain median ms, highest rate held) for `baud`."""
    port = tmp / f"tty{baud}"
    config = tmp / f"dxl-{baud}.toml"
    latency_s = args.latency_timer_ms * 1e-3  # each reply waits that long besides its wire time
    config.write_text(config_text(port, baud, 0.005 + 2 * latency_s, 0.003 + latency_s))
    cpu = [] if args.sim_cpu is None else ["--cpu", str(args.sim_cpu)]
    sim = DxlSimProcess(config, "--latency-timer-ms", f"{args.latency_timer_ms:g}", *cpu)
    try:
        servo_priority(sim, args.sim_priority)
        arm = open_arm(config)
        s = arm.settings
        wire_ms = (s.read_time_s() + s.write_time_s()) * 1e3
        rt = enter_realtime(80, cpus=None)
        try:
            chain_ms, resource_ms, failed = measure_cycles(arm, args.cycle_s)
        finally:
            leave_realtime(rt)
        ratio = float(np.median(chain_ms)) / wire_ms
        parts = f"read {s.read_time_s() * 1e3:.3f} + write {s.write_time_s() * 1e3:.3f}"
        print(f"  {baud / 1e6:g} Mbit/s: wire time {wire_ms:.3f} ms ({parts})")
        print(f"    chain sync read + sync write   {figures(chain_ms, 'ms', 3)}")
        print(f"    resource read() + write()      {figures(resource_ms, 'ms', 3)}")
        verdict = met(ratio <= CYCLE_TARGET)
        print(f"    measured / wire (median) {ratio:.2f}x (target <= {CYCLE_TARGET}x: {verdict})")
        print(f"    failed reads while measuring: {failed}")
        arm.shutdown()
        p99 = float(np.percentile(chain_ms + resource_ms.mean() - chain_ms.mean(), 99))
        best = 0.0
        for rate in (r for r in LADDER_HZ if 1e3 / r >= p99):
            period = 1.0 / rate
            budget = period - s.read_time_s() - s.write_time_s()
            config.write_text(config_text(port, baud, period, min(0.1, 0.8 * budget)))
            try:
                arm = open_arm(config)
            except ConfigError as e:
                print(f"    {rate:g} Hz: refused by the configuration check: {e.detail}")
                continue
            except ResourceError as e:
                print(f"    {rate:g} Hz: the arm does not start: {e}")
                continue
            rt = enter_realtime(80, cpus=None)
            try:
                run = hold_rate(arm, rate, args.seconds, stop_at_first=True)
            finally:
                leave_realtime(rt)
                arm.shutdown()
            held = f"held {args.seconds:g} s" if run.held else f"failed: {run.first_failure}"
            timeout_ms = arm.settings.read_timeout_s * 1e3
            print(f"    {rate:g} Hz ({period * 1e3:.3g} ms, read timeout {timeout_ms:.2g} ms): {held}")
            if run.held:
                best = rate
                break
        soak(config, port, baud, args)
        return wire_ms, float(np.median(chain_ms)), best
    finally:
        sim.stop()


def soak(config: Path, port: Path, baud: int, args: argparse.Namespace) -> None:
    """The target rate for the whole `--seconds`, failures counted (what the ladder stops at)."""
    rate = RATE_TARGET_HZ
    period = 1.0 / rate
    try:
        wire = load_robot_config(config).backend_settings
        budget = period - wire.read_time_s() - wire.write_time_s()
        config.write_text(config_text(port, baud, period, 0.8 * budget))
        arm = open_arm(config)
    except ConfigError as e:
        print(f"    soak at {rate:g} Hz: refused by the configuration check: {e.detail}")
        return
    except ResourceError as e:  # the chain cannot answer within the period (the adapter's latency)
        print(f"    soak at {rate:g} Hz: the arm does not start: {e}")
        return
    rt = enter_realtime(80, cpus=None)
    try:
        run = hold_rate(arm, rate, args.seconds, stop_at_first=False)
    finally:
        leave_realtime(rt)
        arm.shutdown()
    n = arm.settings.comm_errors_in_a_row
    verdict = "no CommLost" if run.longest_failed_run < n else "CommLost"
    print(f"    soak at {rate:g} Hz for {args.seconds:g} s: {run.describe()} ({verdict} at {n} in a row)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="how long a rate must hold")
    ap.add_argument("--cycle-s", type=float, default=5.0, help="back-to-back cycles measured for")
    ap.add_argument("--bauds", default="1000000,2000000,3000000,4000000")
    ap.add_argument("--sim-priority", type=int, default=70, help="SCHED_FIFO of the simulator (0: normal)")
    ap.add_argument(
        "--sim-cpu", type=int, default=None, help="the simulator on this core only (default: any)"
    )
    ap.add_argument(
        "--latency-timer-ms", type=float, default=1.0,
        help="the simulated USB adapter's latency timer (1: as packaging/udev sets it; FTDI's default 16)",
    )  # fmt: skip
    ap.add_argument(
        "--return-delay-us", type=int, default=0,
        help="each servo's Return Delay Time, written by the backend (0: its default; the factory's: 500)",
    )  # fmt: skip
    args = ap.parse_args()
    global RETURN_DELAY_US
    RETURN_DELAY_US = args.return_delay_us
    tmp = Path(tempfile.mkdtemp(prefix="dxlb"))  # short: the control socket's path has ~100 characters
    print(
        "dxl_cycle: 6 servos (dxl-6axis-sim: 3 x XM540-W270, 3 x XM430-W350), simulated chain on a pty, "
        f"latency timer {args.latency_timer_ms:g} ms, return delay {args.return_delay_us} µs"
    )
    results = {}
    try:
        for baud in (int(b) for b in args.bauds.split(",")):
            results[baud] = run_baud(baud, args, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print("  summary:")
    for baud, (wire_ms, median_ms, best) in results.items():
        cycle = f"measured {median_ms:.3f} ms ({median_ms / wire_ms:.2f}x)"
        print(f"    {baud / 1e6:g} Mbit/s: wire {wire_ms:.3f} ms, {cycle}, highest rate held {best:g} Hz")
    if 4_000_000 in results:
        best = results[4_000_000][2]
        verdict = met(best >= RATE_TARGET_HZ)
        print(f"  target 6 servos at 4 Mbit/s >= {RATE_TARGET_HZ:g} Hz: {verdict} ({best:g} Hz held)")
    ratios = [m / w for w, m, _ in results.values()]
    worst = max(ratios)
    print(
        f"  target cycle <= {CYCLE_TARGET}x the wire time: {met(worst <= CYCLE_TARGET)} (worst {worst:.2f}x)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
