"""Six CiA 402 axes at rate: skipped periods against cyclictest's misses, lost and late PDOs, where
the tick's time goes, SDO round trip.

`--buses 1` runs configs/robots/canopen-6axis.toml (six axes on one bus), `--buses 2`
canopen-2bus.toml (three axes on each of two buses, a hub per bus here), at each of `--rates`.
For each rate it prints the bus load the configuration check computes per bus and, when the
check accepts the rate, runs the `canopen402` resource against the simulated drives (`python -m
orccadd.drivesim`, one process on every bus, SCHED_FIFO 70, as the hubs) holding the arm in CSP
at SCHED_FIFO 80 like the daemon's control thread, for `--duration-s`, while a second client on
the first bus (its own process, normal priority, like a service tool) does SDO uploads. Then
`cyclictest` at the same period and priority, half of `--duration-s` just before our loop and
half just after, with the rig up and idle (this VM's noise drifts within minutes).

Definitions (the loop releases tick k at t0 + k·period, absolute):
- a *skipped period* is a release that got no tick: a tick that ends later than the next
  release makes the loop skip every release already past (as the daemon's executor does);
- a cyclictest *miss* is a wake-up later than one period after its release (latency ≥ period):
  a loop with that wake-up would have skipped that many periods however short its work, so
  both count the periods a stall swallows. Target: skipped periods ≤ cyclictest's misses.
- lost PDOs per axis: SYNCs sent on its bus minus TPDOs received (at the end of the run);
- a tick without a fresh TPDO: an axis whose TPDO for the previous tick's SYNC had not arrived
  when the tick's read() returned (an older value is used): the axis had received fewer TPDOs
  than its bus had got SYNCs before the tick (exact while no TPDO is lost, which the run checks);
- where the time goes, per tick: wake-up latency, `read()` (drain every bus, decode, watchdogs),
  `write()` (the RPDOs, SYNC and heartbeat of every bus); SYNC → its answer at the hub (the
  hub's time stamp of a bus's newest TPDO read minus when the SYNC it answers left us); the
  cause of each overrun: the wake-up (≥ half a period late), a read() of a burst (the TPDOs of
  more than two SYNCs at once, after a stall of the drive simulator), write() blocked (a
  voluntary context switch in it: a socket or another thread's lock), preempted (an involuntary
  switch), else the longer of read() (which includes the wait for late TPDOs, `tpdo_wait_us`)
  and write().

Usage: `python benchmarks/canopen_cycle.py [--buses 1|2] [--rates 250,500,1000] [--duration-s 60]
[--tpdo-wait-us N]` (root for SCHED_FIFO; `make bench`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import canopen
import numpy as np
from harness import ROOT, cyclictest, figures

from orccadd.errors import ConfigError
from orccadd.physres.canopen402 import Canopen402Arm
from orccadd.robot import create_resource, load_robot_config
from orccadd.runtime import WallClock, enter_realtime, leave_realtime
from orccadd.types import CommandMode
from tests.canopen_rig import CANOPEN_2BUS, CANOPEN_6AXIS, canopen_rig

PRIORITY = 80
CLOCK_TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """User + system CPU time of process `pid` so far (s)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_PER_S


def sdo_client(config: str, duration_s: float) -> None:
    """A second client on the first bus: expedited uploads of 0x1000 every 50 ms, round trips
    (ms) printed as one JSON list at the end."""
    cfg = load_robot_config(Path(config))
    net = canopen.Network()
    net.connect(**cfg.backend_settings.bus_kwargs())
    node = canopen.RemoteNode(1, cfg.backend_settings.eds_paths[0])
    net.add_node(node)
    rtts: list[float] = []
    end = time.monotonic() + duration_s
    try:
        while time.monotonic() < end:
            t0 = time.perf_counter()
            node.sdo.upload(0x1000, 0)
            rtts.append((time.perf_counter() - t0) * 1e3)
            time.sleep(0.05)
    except canopen.SdoCommunicationError:
        pass
    finally:
        net.disconnect()
    print(json.dumps(rtts), flush=True)


def with_period(rig_config: Path, period_s: float, tpdo_wait_us: int | None) -> None:
    """The rig's config at `period_s`, waiting `tpdo_wait_us` for late TPDOs (None: as shipped)."""
    text = rig_config.read_text()
    for old in ("control_period_s = 0.002", "control_period_s = 0.001"):
        text = text.replace(old, f"control_period_s = {period_s:g}")
    if tpdo_wait_us is not None:
        text = re.sub(r"\ntpdo_wait_us = \d+", "", text)
        text = text.replace(
            "[resource.settings]\n", f"[resource.settings]\ntpdo_wait_us = {tpdo_wait_us}\n", 1
        )
    rig_config.write_text(text)


def run_rate(robot: Path, rate_hz: float, duration_s: float, tpdo_wait_us: int | None) -> None:
    period_s = 1.0 / rate_hz
    period_ns = round(period_s * 1e9)
    with tempfile.TemporaryDirectory() as tmp, canopen_rig(Path(tmp), robot=robot) as rig:
        with_period(rig.config, period_s, tpdo_wait_us)
        try:
            cfg = load_robot_config(rig.config)
        except ConfigError as e:
            print(f"  {rate_hz:g} Hz: refused by the configuration check: {e.detail}")
            return
        before = cyclictest(period_s, duration_s / 2, PRIORITY)
        print(f"    tpdo_wait_us = {cfg.backend_settings.tpdo_wait_us}")
        arm = create_resource(cfg)
        assert isinstance(arm, Canopen402Arm)
        arm.configure()
        arm.activate(CommandMode.POSITION)
        hold = arm.read(time.monotonic()).q_rad.copy()
        sdo = subprocess.Popen(
            [sys.executable, __file__, "--sdo-client", str(rig.config), "--duration-s", str(duration_s)],
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        m = arm.master
        axes, ports = m.axes, m.ports
        first_of = [p.axes[0] for p in ports]  # an axis per bus, for the SYNC -> TPDO time
        n = int(duration_s * rate_hz)
        rec = np.zeros((n, 4), dtype=np.int64)  # release, woke, read done, write done (ns)
        # voluntary context switches in write(), involuntary in the tick, TPDOs read, voluntary in read()
        switches = np.zeros((n, 4), dtype=np.int64)
        round_trip_s: list[list[float]] = [[] for _ in ports]
        late = np.zeros(len(axes), dtype=np.int64)
        count0 = np.array([a.tpdo_count for a in axes])
        syncs0 = np.array([p.syncs_sent for p in ports])
        clock = WallClock()
        pids = {"controller": os.getpid(), "drive simulator": rig.drives.proc.pid, "SDO client": sdo.pid}
        pids |= {f"hub {p.conf.channel}": hub.proc.pid for p, hub in zip(ports, rig.hubs, strict=False)}
        cpu0 = {name: cpu_s(pid) for name, pid in pids.items()}
        rt = enter_realtime(PRIORITY, cpus=None)
        t0 = time.monotonic()
        release = time.monotonic_ns() + period_ns
        ticks = overruns = skipped = comm_lost = 0
        sync_wall_s = np.zeros(n + 1)  # when our k-th SYNC left (wall clock, as the hub stamps)
        thread = resource.RUSAGE_THREAD
        try:
            for k in range(n):
                clock.sleep_until_ns(release)
                woke = time.monotonic_ns()
                ru0 = resource.getrusage(thread)
                seen = [a.tpdo_count for a in axes]
                st = arm.read(release * 1e-9)
                read_done = time.monotonic_ns()
                ru_read = resource.getrusage(thread)
                for j, a in enumerate(axes):  # the k-th TPDO answers the k-th SYNC (none lost)
                    late[j] += a.tpdo_count - count0[j] < ports[a.port].syncs_sent - syncs0[a.port]
                for b, j in enumerate(first_of):
                    answered = axes[j].tpdo_count - count0[j]  # the newest answers SYNC number `answered`
                    if axes[j].tpdo_count != seen[j] and 0 < answered <= k:
                        round_trip_s[b].append(axes[j].position_time_s - sync_wall_s[answered - 1])
                comm_lost += bool(st.status & 8)
                arm.write(release * 1e-9, hold)
                sync_wall_s[k] = time.time()
                done = time.monotonic_ns()
                ru1 = resource.getrusage(thread)
                rec[k] = (release, woke, read_done, done)
                tpdos_read = sum(a.tpdo_count for a in axes) - sum(seen)
                switches[k] = (
                    ru1.ru_nvcsw - ru_read.ru_nvcsw,
                    ru1.ru_nivcsw - ru0.ru_nivcsw,
                    tpdos_read,
                    ru_read.ru_nvcsw - ru0.ru_nvcsw,
                )
                ticks += 1
                release += period_ns
                if release < done:
                    overruns += 1
                    while release < time.monotonic_ns():
                        release += period_ns
                        skipped += 1
        finally:
            leave_realtime(rt)
            elapsed = time.monotonic() - t0
            cpu = {name: (cpu_s(pid) - cpu0[name]) / elapsed for name, pid in pids.items()}
            time.sleep(0.05)  # the last SYNC's TPDOs are on their way: read them (no SYNC sent)
            arm.read(time.monotonic())
            syncs = np.array([p.syncs_sent for p in ports]) - syncs0
            tpdos = np.array([a.tpdo_count for a in axes]) - count0
            status = rig.drives.status()
            arm.shutdown()
        out, _ = sdo.communicate(timeout=duration_s + 30)
        rtts = json.loads(out.strip().splitlines()[-1]) if out.strip() else []
        after = cyclictest(period_s, duration_s / 2, PRIORITY)
    report(rate_hz, period_ns, rec[:ticks], switches[:ticks], elapsed, overruns, skipped, before, after)
    lost = [int(syncs[a.port] - tpdos[j]) for j, a in enumerate(axes)]
    print(f"    SYNCs sent per bus {syncs.tolist()}; TPDOs lost per axis (its bus's SYNCs - TPDOs): {lost}")
    print(f"    ticks without a fresh TPDO per axis: {late.tolist()} of {ticks}; comm-lost ticks {comm_lost}")
    for b, port in enumerate(ports):
        trip_ms = np.array(round_trip_s[b]) * 1e3
        print(f"    {port.conf.channel}: SYNC -> its answer (TPDO) at the hub {figures(trip_ms, 'ms', 2)}")
    ages = status["frame_age_ms"]
    print(
        "    frame age at the drives (hub -> drive simulator): "
        + ", ".join(f"{k} {v:.2f} ms" for k, v in ages.items())
    )
    print(
        f"    drive simulator: longest gap between its loop's passes {status['longest_loop_gap_ms']:.1f} ms"
    )
    print(f"    SDO round trip (upload 0x1000 from a second client process) {figures(rtts, 'ms', 2)}")
    print("    CPU (share of one core) " + ", ".join(f"{name} {share:.0%}" for name, share in cpu.items()))


def report(
    rate_hz: float,
    period_ns: int,
    rec: np.ndarray,
    switches: np.ndarray,
    elapsed_s: float,
    overruns: int,
    skipped: int,
    before: np.ndarray | None,
    after: np.ndarray | None,
) -> None:
    ticks = len(rec)
    period_us = period_ns / 1e3
    n_axes = int(np.median(switches[:, 2])) or 1
    wake = (rec[:, 1] - rec[:, 0]) / 1e3
    read = (rec[:, 2] - rec[:, 1]) / 1e3
    write = (rec[:, 3] - rec[:, 2]) / 1e3
    end = (rec[:, 3] - rec[:, 0]) / 1e3
    print(f"  {rate_hz:g} Hz: {ticks} ticks in {elapsed_s:.1f} s = {ticks / elapsed_s:.1f} Hz achieved")
    base = None if before is None or after is None else np.concatenate([before, after])
    if base is None:
        misses = "cyclictest not run"
    else:
        nb, na = int((before >= period_us).sum()), int((after >= period_us).sum())  # type: ignore[operator]
        misses = f"cyclictest's misses {nb + na} of {len(base)} ({nb} before, {na} after)"
        verdict = "met" if skipped <= nb + na else "NOT met"
        misses += f" -> skipped <= misses: {verdict}"
    print(f"    skipped periods {skipped} (in {overruns} overrunning ticks) of {ticks + skipped}; {misses}")
    print(f"    wake-up latency {figures(wake, 'µs')}")
    if base is not None:
        print(f"    cyclictest      {figures(base, 'µs')}")
    print(f"    read()          {figures(read, 'µs')}")
    print(f"    write()         {figures(write, 'µs')}")
    print(f"    release -> end  {figures(end, 'µs')}")
    causes: Counter[str] = Counter()
    over = np.flatnonzero(rec[:, 3] - rec[:, 0] > period_ns)
    for k in over[:5]:
        print(
            f"    overrun at tick {k}: wake-up {wake[k]:.0f} µs, read() {read[k]:.0f} µs "
            f"({switches[k, 2]} TPDOs), write() {write[k]:.0f} µs"
        )
    for k in over:
        if wake[k] >= period_us / 2:
            causes["wake-up late"] += 1
        elif read[k] >= write[k] and switches[k, 2] > 2 * n_axes:  # the TPDOs of > 2 SYNCs at once
            causes["read() of a burst of TPDOs"] += 1
        elif switches[k, 0]:
            causes["write() blocked"] += 1
        elif switches[k, 1]:
            causes["preempted in the tick"] += 1
        else:
            causes["read() long" if read[k] >= write[k] else "write() long"] += 1
    waited, blocked = int((switches[:, 3] > 0).sum()), int((switches[:, 0] > 0).sum())
    print(
        f"    overrun causes: {dict(causes) or 'none'}; ticks that slept in read() (waiting for TPDOs) "
        f"{waited}, in write() {blocked}"
    )
    print(f"    TPDOs read per tick {figures(switches[:, 2], 'frames', 0)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--buses", type=int, choices=(1, 2), default=1)
    ap.add_argument("--rates", default="")
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--tpdo-wait-us", type=int, default=None, help="override the config's tpdo_wait_us")
    ap.add_argument("--sdo-client", metavar="CONFIG", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.sdo_client:
        sdo_client(args.sdo_client, args.duration_s)
        return 0
    robot = CANOPEN_2BUS if args.buses == 2 else CANOPEN_6AXIS
    rates = args.rates or ("1000" if args.buses == 2 else "250,500,1000")
    from orccadd.drivers.canopen.busload import bus_load
    from orccadd.drivers.canopen.settings import CanopenSettings

    layout = "three axes on each of two buses" if args.buses == 2 else "six axes on one bus"
    print(f"canopen_cycle: {robot.name}, {layout}, simulated drives, SYNC + 8-byte RPDO + TPDO per axis")
    for rate in (float(r) for r in rates.split(",")):
        per_bus = [3, 3] if args.buses == 2 else [6]
        loads = [bus_load(CanopenSettings(axes=()).traffic(n), 1.0 / rate, 1_000_000) for n in per_bus]
        print(f"  {rate:g} Hz: " + "; ".join(f"can{b}: {ld.describe()}" for b, ld in enumerate(loads)))
        run_rate(robot, rate, args.duration_s, args.tpdo_wait_us)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
