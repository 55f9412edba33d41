"""Six CiA 402 axes through the virtual bus: cycle rate, jitter, late or lost PDOs, SDO round trip.

For each control rate (250, 500, 1000 Hz by default) it prints the bus load the configuration
check computes for canopen-6axis's PDO layout at 1 Mbit/s, and, when the check accepts the rate,
runs the `canopen402` resource against the simulated drives (`python -m orccadd.drivesim`) over
the userspace hub (or vcan0) for `--duration-s`, holding the arm in CSP at SCHED_FIFO 80 like the
daemon's control thread:

- achieved cycle rate, and the loop's wake-up jitter (median / p99 / max);
- late TPDOs: ticks where an axis had no fresh TPDO; lost: SYNCs sent minus TPDOs received, per axis;
- SDO round trip (an expedited upload of 0x1000 from a second client on the bus, during the run).

Target: 6 axes at 500 Hz with no lost cycles over 60 s. Usage: `python benchmarks/canopen_cycle.py
[--rates 250,500,1000] [--duration-s 60]` (root for SCHED_FIFO; `make bench`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

import canopen
import numpy as np
from harness import figures

from orccadd.errors import ConfigError
from orccadd.physres.canopen402 import Canopen402Arm
from orccadd.robot import create_resource, load_robot_config
from orccadd.runtime import WallClock, enter_realtime, leave_realtime
from orccadd.types import CommandMode
from tests.canopen_rig import canopen_rig


def sdo_round_trips(rig_config: Path, stop: threading.Event, out: list[float]) -> None:
    cfg = load_robot_config(rig_config)
    net = canopen.Network()
    net.connect(**cfg.backend_settings.bus_kwargs())
    node = canopen.RemoteNode(1, cfg.backend_settings.eds_paths[0])
    net.add_node(node)
    try:
        while not stop.is_set():
            t0 = time.perf_counter()
            node.sdo.upload(0x1000, 0)
            out.append((time.perf_counter() - t0) * 1e3)
            time.sleep(0.05)
    except canopen.SdoCommunicationError:
        pass
    finally:
        net.disconnect()


def run_rate(rate_hz: float, duration_s: float) -> None:
    period = 1.0 / rate_hz
    with tempfile.TemporaryDirectory() as tmp, canopen_rig(Path(tmp)) as rig:
        text = rig.config.read_text().replace("control_period_s = 0.002", f"control_period_s = {period:g}")
        rig.config.write_text(text)
        try:
            cfg = load_robot_config(rig.config)
        except ConfigError as e:
            print(f"  {rate_hz:g} Hz: refused by the configuration check: {e.detail}")
            return
        arm = create_resource(cfg)
        assert isinstance(arm, Canopen402Arm)
        arm.configure()
        arm.activate(CommandMode.POSITION)
        hold = arm.read(time.monotonic()).q_rad.copy()
        stop = threading.Event()
        rtts: list[float] = []
        sdo = threading.Thread(target=sdo_round_trips, args=(rig.config, stop, rtts), daemon=True)
        sdo.start()
        n = int(duration_s * rate_hz)
        wake = np.zeros(n)
        axes = arm.master.axes
        late = np.zeros(len(axes), dtype=np.int64)
        count0 = np.array([a.tpdo_count for a in axes])
        syncs0 = arm.master.syncs_sent
        clock = WallClock()
        sys.setswitchinterval(0.0002)  # as the daemon: the SDO client thread gets the lock back fast
        rt = enter_realtime(80, cpus=None)
        t0 = time.monotonic()
        nxt_ns = time.monotonic_ns() + int(period * 1e9)
        ticks = comm_lost = overruns = 0
        try:
            for k in range(n):
                clock.sleep_until_ns(nxt_ns)
                wake[k] = (time.monotonic_ns() - nxt_ns) * 1e-3
                seen = [a.tpdo_count for a in axes]
                st = arm.read(nxt_ns * 1e-9)
                for j, a in enumerate(axes):
                    late[j] += int(a.tpdo_count == seen[j])
                comm_lost += int(bool(st.status & 8))
                arm.write(nxt_ns * 1e-9, hold)
                ticks += 1
                nxt_ns += int(period * 1e9)
                if nxt_ns < time.monotonic_ns():
                    overruns += 1
                    while nxt_ns < time.monotonic_ns():
                        nxt_ns += int(period * 1e9)
        finally:
            leave_realtime(rt)
            elapsed = time.monotonic() - t0
            stop.set()
            sdo.join(5)
            syncs = arm.master.syncs_sent - syncs0
            tpdos = np.array([a.tpdo_count for a in axes]) - count0
            ages = rig.drives.status()["frame_age_ms"]
            arm.shutdown()
        print(
            f"  {rate_hz:g} Hz: {ticks} cycles in {elapsed:.1f} s = {ticks / elapsed:.1f} Hz achieved "
            f"({overruns} overruns skipped periods)"
        )
        print(f"    wake-up jitter {figures(wake, 'µs')}")
        print(f"    SYNCs sent {syncs}; TPDOs lost per axis (SYNCs - TPDOs): {(syncs - tpdos).tolist()}")
        print(f"    ticks without a fresh TPDO (late) per axis: {late.tolist()}; comm-lost ticks {comm_lost}")
        print(
            "    frame age at the drives (hub forward -> drive simulator reads it, last frames): "
            + ", ".join(f"{k} {v:.2f} ms" for k, v in ages.items())
        )
        print(f"    SDO round trip (upload 0x1000 from a second client) {figures(rtts, 'ms', 2)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="250,500,1000")
    ap.add_argument("--duration-s", type=float, default=60.0)
    args = ap.parse_args()
    from orccadd.drivers.canopen.busload import bus_load
    from orccadd.drivers.canopen.settings import AxisConfig, CanopenSettings

    six = CanopenSettings(axes=tuple(AxisConfig(node_id=i + 1, eds="-") for i in range(6)))

    print("canopen_cycle: 6 CiA 402 axes (canopen-6axis, simulated drives), SYNC + 8-byte RPDO + TPDO each")
    for rate in (float(r) for r in args.rates.split(",")):
        load = bus_load(six.traffic(), 1.0 / rate, 1_000_000)
        print(f"  {rate:g} Hz: {load.describe()}")
        run_rate(rate, args.duration_s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
