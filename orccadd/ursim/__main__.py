"""`python -m orccadd.ursim --config ROBOT.toml`: a simulated UR controller on 127.0.0.1.

It serves RTDE on 30004, the dashboard server on 29999 and the script ports 30001-30003 (the
ports stock ur_rtde uses; all can be moved), as an e-Series controller (PolyScope 5.26,
500 Hz) or, with --cb3, a CB3 (3.15, 125 Hz). The arm is the robot config's (joints, limits,
URDF); --plant gives the `sim` settings of its dynamics (friction, initial_q_rad). The robot
boots powered off, as a real one does, unless --boot running.

It prints `ursim: ready, control 127.0.0.1:PORT` once every port listens; the control port
takes the fault injections (see `orccadd.ursim.faults`). A port already in use is an error.
"""

from __future__ import annotations

import argparse
import faulthandler
import gc
import logging
import signal
import socket
import sys
import threading
from functools import partial
from pathlib import Path

from orccadd.config.robot import read_toml
from orccadd.config.station import pick_resource, read_station_config
from orccadd.errors import OrccaddError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.runtime import sim_control
from orccadd.runtime.rt import realtime_device_process
from orccadd.runtime.threads import ThreadGroup
from orccadd.ursim import faults
from orccadd.ursim.series import CB3, E_SERIES
from orccadd.ursim.simulator import DEFAULT_PORTS, UrSimulator

JOIN_S = 5.0  # how long the exit waits for the control clients' threads
log = logging.getLogger("orccadd.ursim")

UR_DOF = 6


def _loopback(host: str) -> str:
    if host != "localhost" and not host.startswith("127."):
        raise argparse.ArgumentTypeError(
            f"{host} is not a loopback address: the simulator serves 127.0.0.1 only"
        )
    return host


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m orccadd.ursim",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--config", required=True, help="the robot config (joints, limits, URDF)")
    ap.add_argument(
        "--resource",
        default="",
        help="in a station config (several resources): the resource to serve (default: its only ur_rtde one)",
    )
    ap.add_argument(
        "--host", type=_loopback, default="127.0.0.1", help="a loopback address (default 127.0.0.1)"
    )
    ap.add_argument("--rtde-port", type=int, default=DEFAULT_PORTS["rtde"])
    ap.add_argument("--dashboard-port", type=int, default=DEFAULT_PORTS["dashboard"])
    ap.add_argument("--primary-port", type=int, default=DEFAULT_PORTS["primary"])
    ap.add_argument("--secondary-port", type=int, default=DEFAULT_PORTS["secondary"])
    ap.add_argument(
        "--script-port",
        type=int,
        default=DEFAULT_PORTS["realtime"],
        help="the real-time port ur_rtde uploads to",
    )
    ap.add_argument(
        "--control-port", type=int, default=0, help="fault injection and status (default: any free)"
    )
    ap.add_argument("--cb3", action="store_true", help="a CB3 controller: version 3.15, 125 Hz")
    ap.add_argument(
        "--software",
        default="",
        help="the controller's software version (default: e-Series 5.26.0, CB3 3.15.7); "
        "5.26 or later has direct torque control",
    )
    ap.add_argument(
        "--plant", default="", help="TOML table of `sim` settings for the arm (friction, initial_q_rad)"
    )
    ap.add_argument(
        "--unlock-delay-s",
        type=float,
        default=5.0,
        help="how long after a protective stop it may be unlocked (UR: 5 s)",
    )
    ap.add_argument(
        "--boot", choices=("power_off", "running"), default="power_off", help="the robot mode at boot"
    )
    ap.add_argument(
        "--priority",
        type=int,
        default=0,
        help="SCHED_FIFO priority of the simulator's threads (0: time-shared); a real controller "
        "keeps its cycle whatever the robot PC does, this one only if it is real-time too",
    )
    ap.add_argument(
        "--cpu",
        type=int,
        default=None,
        help="run on this core only (a device has its own processor; default: any core)",
    )
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        setup_logging("orccadd.ursim")
    except LogSetupError as e:
        raise SystemExit(f"python -m orccadd.ursim: error: {e}") from None
    try:
        cfg = pick_resource(read_station_config(args.config), ("ur_rtde",), args.resource)
        if cfg.dof != UR_DOF:
            raise OrccaddError(f"{args.config}: a UR arm has {UR_DOF} joints, this config {cfg.dof}")
        plant = read_toml(Path(args.plant)) if args.plant else {}
        ports = {
            "rtde": args.rtde_port,
            "dashboard": args.dashboard_port,
            "primary": args.primary_port,
            "secondary": args.secondary_port,
            "realtime": args.script_port,
        }
        series = CB3 if args.cb3 else E_SERIES
        if args.software:
            try:
                series = series.with_software(args.software)
            except ValueError as e:
                raise OrccaddError(f"--software: {e}") from None
        sim = UrSimulator(
            cfg,
            series,
            host=args.host,
            ports=ports,
            sim_settings=plant,
            sim_settings_file=args.plant,
            unlock_delay_s=args.unlock_delay_s,
            boot_running=args.boot == "running",
        )
    except OrccaddError as e:
        log.error("%s", e)
        return 1
    if args.priority or args.cpu is not None:
        for warning in realtime_device_process(args.priority, args.cpu):
            log.warning("%s", warning)
    try:
        sim.open()
    except OrccaddError as e:
        log.error("%s", e)
        return 1
    try:
        control = socket.create_server(("127.0.0.1", args.control_port))
    except OSError as e:
        log.error("control port %d: %s", args.control_port, e.strerror)
        sim.close()
        return 1
    faulthandler.register(signal.SIGUSR1)  # `kill -USR1 PID`: every thread's stack to the log
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    threads = ThreadGroup("ursim")
    threads.start(
        sim_control.serve, control, partial(faults.inject, sim), sim.status, threads, name="control"
    )
    gc.collect()
    gc.freeze()  # the model and tables are long-lived: keep the collector's passes short
    # the cycle's thread waits at most this long for the interpreter when a server thread holds
    # it (the default, 5 ms, is longer than an e-Series cycle)
    sys.setswitchinterval(0.0005)
    series = sim.ctl.series
    log.info(
        "%s %s at %g Hz on %s: %s",
        series.name,
        series.version_text,
        series.rate_hz,
        args.host,
        ", ".join(f"{n} {s.port}" for n, s in sim.servers.items()),
    )
    print(f"ursim: ready, control 127.0.0.1:{control.getsockname()[1]}", flush=True)
    try:
        sim.run(stop.is_set)
    finally:
        control.close()
        sim.close()
        threads.join(JOIN_S)
        sim.threads.join(JOIN_S)
    log.info("stopped after %d cycles", sim.ctl.cycles)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
