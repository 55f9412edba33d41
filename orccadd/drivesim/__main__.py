"""`python -m orccadd.drivesim --config ROBOT.toml`: the simulated drives of a `canopen402` robot.

It reads the same robot config as orccadd (bus, node ids, EDS/DCF files, encoder and gear
units; the URDF for the arm), joins the bus, boots every node and answers like the drives
would. A control port on 127.0.0.1 speaks the simulators' control protocol
(`orccadd.runtime.sim_control`), for tests:

    {"inject": FAULT, "device": 3}   overcurrent | following_error | heartbeat_silence | node_silence
                                     | sto | clear
    {"inject": ..., "device": 1, "bus": "can1"}   (the bus's channel, when node ids repeat across buses)
    {"status": true}   -> positions (rad), each drive's CiA 402 state, SYNCs seen (in all and per bus)

A config with several buses (`[[resource.settings.buses]]`) gets one simulator on all of them:
the drives of every bus move the one arm.

It prints `drivesim: ready, control 127.0.0.1:PORT` once the nodes have booted.

The drives are strict as real ones are (see `axis.Strictness`); `--lenient heartbeat_consumer`,
`--lenient cob_id_valid_bit` or `--lenient supported_modes` relaxes one. A new mode (0x6060) is
shown in 0x6061 before its write is confirmed; `--mode-display-delay-ms` makes the drives show it
that much later instead (`inf`: never), for a master's test against drives that lag.
"""

from __future__ import annotations

import argparse
import gc
import logging
import os
import signal
import socket
import threading
from dataclasses import fields, replace
from functools import partial
from pathlib import Path
from typing import Any

import can
import numpy as np

from orccadd.config.robot import RobotConfig, read_toml
from orccadd.config.station import pick_resource
from orccadd.drivers.canopen.settings import CanopenSettings
from orccadd.drivesim.axis import AxisUnits, Strictness
from orccadd.drivesim.simulator import AxisSpec, DriveSimulator
from orccadd.drivesim.socketcand import QueuedSocketcandBus
from orccadd.errors import OrccaddError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.physres.sim import SimSettings, load_sim_settings
from orccadd.robot import load_station_config
from orccadd.runtime import Summary, sim_control
from orccadd.runtime.rt import realtime_device_process
from orccadd.runtime.threads import ThreadGroup

log = logging.getLogger("orccadd.drivesim")


def plant_config(cfg: RobotConfig, plant_file: str) -> RobotConfig:
    """The robot with `sim` settings for the arm behind the drives (friction, initial pose)."""
    raw = read_toml(Path(plant_file)) if plant_file else {}
    # 0.5 ms sub-steps: stable with the drives' servo gains on light wrist joints (1 ms is not),
    # and light enough for a process that must also answer every SYNC in time (the `sim`
    # default, 0.2 ms, costs a whole core of this machine)
    raw = {"substep_s": min(0.0005, cfg.control_period_s), **raw}
    settings = load_sim_settings(SimSettings, raw, cfg, plant_file or cfg.source)
    resource = replace(cfg.resource, backend="sim", settings=raw)
    return replace(cfg, resource=resource, backend_settings=settings)


def _inject(sim: DriveSimulator, req: sim_control.Injection) -> None:
    if req.device is None:
        raise ValueError('a drive fault names its drive: "device": NODE_ID')
    unknown = set(req.params) - {"bus"}
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)} (a drive fault takes: bus)")
    sim.inject(req.fault, req.device, str(req.params.get("bus", "")))


def _status(sim: DriveSimulator) -> dict[str, Any]:
    with sim.lock:
        return {
            "q_rad": [float(x) for x in sim.arm.q],
            "dq_rad_s": [float(x) for x in sim.arm.dq],
            "devices": [
                sim_control.device(ax.node.node_id, ax.sm.state.name, ax.fault_text()) for ax in sim.axes
            ],
            "states": [ax.sm.state.name for ax in sim.axes],
            "syncs": sim.syncs,
            "bus_syncs": dict(zip(sim.bus_names, sim.bus_syncs, strict=True)),
            "bus_error": sim.bus_error,
            "frame_age_ms": _figures_ms(list(sim.frame_age_s)),
            "longest_loop_gap_ms": sim.longest_gap_s * 1e3,
            "paused_ms": sim.arm.paused_s * 1e3,
        }


def _figures_ms(values_s: list[float]) -> dict[str, float]:
    if not values_s:
        return {}
    fig = Summary.of(np.asarray(values_s) * 1e9)
    return {"median": fig.median_us / 1e3, "p99": fig.p99_us / 1e3, "max": fig.max_us / 1e3}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m orccadd.drivesim",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--config", required=True, help="a canopen402 robot config")
    ap.add_argument(
        "--resource",
        default="",
        help="in a station config (several resources): the resource to serve "
        "(default: its only canopen402 one)",
    )
    ap.add_argument(
        "--plant", default="", help="TOML table of `sim` settings for the arm (friction, initial_q_rad)"
    )
    ap.add_argument("--control-port", type=int, default=0)
    ap.add_argument(
        "--priority",
        type=int,
        default=0,
        help="SCHED_FIFO priority (drives are hardware: their timing "
        "should not depend on the controller's load); 0: normal",
    )
    ap.add_argument("--nice", type=int, default=0, help="scheduling weight at normal priority (-20..19)")
    switches = [f.name for f in fields(Strictness) if isinstance(f.default, bool)]
    ap.add_argument(
        "--lenient",
        action="append",
        default=[],
        choices=switches,
        help="relax one of the drives' strict behaviours",
    )
    ap.add_argument(
        "--mode-display-delay-ms",
        type=float,
        default=Strictness.mode_display_delay_s * 1e3,
        help="how late the drives show a new mode of operation (0x6061); 0 (default): at once, "
        "before the write is confirmed; inf: never",
    )
    args = ap.parse_args(argv)
    strict = Strictness(
        **{name: name not in args.lenient for name in switches},
        mode_display_delay_s=args.mode_display_delay_ms / 1e3,
    )
    try:
        setup_logging("orccadd.drivesim")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    try:
        cfg = pick_resource(load_station_config(args.config), ("canopen402",), args.resource)
        s = cfg.backend_settings
        if not isinstance(s, CanopenSettings):
            raise OrccaddError(f"{args.config}: resource.backend must be canopen402 for simulated drives")
        buses = s.bus_list()
        on_bus = {i: k for k, b in enumerate(buses) for i in b.axes}
        specs = [
            AxisSpec(
                ax.node_id, path, AxisUnits(ax.counts_per_rev, ax.gear_ratio, ax.rated_torque_nm), on_bus[i]
            )
            for i, (ax, path) in enumerate(zip(s.axes, s.eds_paths, strict=True))
        ]
        opened = [
            QueuedSocketcandBus(b.channel, b.host, b.port)  # one write per cycle, not per frame
            if b.interface == "socketcand"
            else can.Bus(**b.bus_kwargs())
            for b in buses
        ]
        names = [b.channel for b in buses]
        sim = DriveSimulator(plant_config(cfg, args.plant), specs, opened, strict, names)
    except (OrccaddError, can.CanError, OSError) as e:
        log.error("%s", e)
        return 1
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    srv = socket.create_server(("127.0.0.1", args.control_port))
    threads = ThreadGroup("drivesim")
    threads.start(
        sim_control.serve, srv, partial(_inject, sim), partial(_status, sim), threads, name="control"
    )
    if args.nice:
        try:
            os.nice(args.nice)
        except OSError as e:
            log.warning("nice %d refused (%s)", args.nice, e.strerror)
    if args.priority:
        for w in realtime_device_process(args.priority):
            log.warning("%s", w)
    # six object dictionaries and a Pinocchio model are many long-lived objects: frozen, the
    # collector's full passes skip them (they stalled this loop for up to ~0.1 s)
    gc.collect()
    gc.freeze()
    runner = threads.start(sim.run, stop.is_set, name="bus")
    print(f"drivesim: ready, control 127.0.0.1:{srv.getsockname()[1]}", flush=True)
    while not stop.wait(0.2):
        if not runner.is_alive():
            break
    stop.set()
    threads.join(5.0)  # the bus loop, the control server and its clients
    srv.close()
    for bus in opened:
        bus.shutdown()
    log.info("stopped after %d SYNCs", sim.syncs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
