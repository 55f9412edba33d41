"""`python -m orccadd.dxlsim --config ROBOT.toml`: the simulated servos of a `dynamixel` robot.

It reads the robot config's form (`read_robot_config`: any backend name) and the keys of
`[resource.settings]` listed in `orccadd.dxlsim.settings`, makes a pseudo-terminal, links it
at `port` (or `--port`), and answers as the servos would, moving the arm of the config's URDF.
Faults are injected through a UNIX socket (`--control`, default PORT.control; see
`orccadd.dxlsim.control`). It prints `dxlsim: ready, port PATH, control PATH` once serving, and
removes both on SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import gc
import logging
import signal
import threading

from orccadd.config.station import pick_resource, read_station_config
from orccadd.dxlsim.chain import Chain
from orccadd.dxlsim.control import ControlServer
from orccadd.dxlsim.link import PtyLink
from orccadd.dxlsim.server import Server
from orccadd.dxlsim.settings import read_chain_settings
from orccadd.errors import OrccaddError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.runtime.rt import realtime_device_process

log = logging.getLogger("orccadd.dxlsim")


def _floats(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of numbers") from None


def _firmware_item(text: str) -> tuple[int, int]:
    dxl_id, _, version = text.partition("=")
    try:
        return int(dxl_id), int(version)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not ID=VERSION (e.g. 3=44)") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m orccadd.dxlsim",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--config", required=True, help="a robot config whose resource is a DYNAMIXEL chain")
    ap.add_argument(
        "--resource",
        default="",
        help="in a station config (several resources): the resource to serve "
        "(default: its only dynamixel one)",
    )
    ap.add_argument("--port", default="", help="where to link the serial port (default: the config's port)")
    ap.add_argument("--control", default="", help="the fault-injection socket (default: PORT.control)")
    ap.add_argument(
        "--initial-q-rad", type=_floats, default=None, help="joint angles at start (default: home)"
    )
    ap.add_argument(
        "--priority",
        type=int,
        default=0,
        help="SCHED_FIFO priority of the simulator (0: time-shared); real servos answer whatever "
        "the robot PC does, this simulator only if it is real-time too (beside orccadd's loop)",
    )
    ap.add_argument(
        "--firmware",
        action="append",
        default=[],
        type=_firmware_item,
        metavar="ID=VERSION",
        help="a servo's Firmware Version, where not its model's (e.g. 3=44: no Fast Sync Read, "
        "which came with 45); may be given for several servos",
    )
    ap.add_argument(
        "--cpu",
        type=int,
        default=None,
        help="run on this core only (a device has its own processor; default: any core)",
    )
    ap.add_argument(
        "--latency-timer-ms",
        type=float,
        default=0.0,
        help="the USB adapter's latency timer between the servos and the controller: each reply "
        "reaches it that much later (an FTDI adapter holds a short packet until its timer; its "
        "default is 16 ms, 1 ms once set; default here 0: no adapter)",
    )
    args = ap.parse_args(argv)
    try:
        setup_logging("orccadd.dxlsim")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    try:
        cfg = pick_resource(read_station_config(args.config), ("dynamixel",), args.resource)
        settings = read_chain_settings(cfg)
        if args.initial_q_rad is not None and len(args.initial_q_rad) != cfg.dof:
            raise OrccaddError(
                f"--initial-q-rad has {len(args.initial_q_rad)} angles, the arm {cfg.dof} joints"
            )
        chain = Chain(cfg, settings, args.initial_q_rad, dict(args.firmware))
        port = args.port or settings.port
        link = PtyLink(port)
    except (OrccaddError, OSError) as e:
        log.error("%s", e)
        return 1
    control_path = args.control or f"{port}.control"
    try:
        control = ControlServer(control_path)
    except OSError as e:
        log.error("%s: %s", control_path, e)
        link.close()
        return 1
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    server = Server(chain, link, control, latency_s=args.latency_timer_ms * 1e-3)
    if args.priority or args.cpu is not None:
        for warning in realtime_device_process(args.priority, args.cpu):
            log.warning("%s", warning)
    gc.collect()
    gc.freeze()  # the model and tables are long-lived: keep the collector's passes short
    print(f"dxlsim: ready, port {port}, control {control_path}", flush=True)
    try:
        server.run(stop.is_set)
    finally:
        control.close()
        link.close()
    log.info("stopped after %d packets (%d with a bad CRC)", chain.packets, chain.crc_errors)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
