"""`python -m orccadd.ecatsim --config ROBOT.toml`: the simulated EtherCAT drives of an
`ethercat402` robot, on a virtual Ethernet link (root: it makes a network namespace).

It reads the same robot config as orccadd (the interface, each slave's identity, dictionary and
units; the URDF for the arm), makes the namespace and the veth pair of
`[resource.settings.simulator]` (the master's end named as the config's `interface`), and
answers every EtherCAT frame as a line of CiA 402 drives would. A control port on 127.0.0.1
speaks the simulators' control protocol (`orccadd.runtime.sim_control`), "device" being a
slave's place on the line (1 = next to the master):

    {"inject": "overcurrent", "device": 2}     the drive faults (EMCY 0x2310, fault reaction)
    {"inject": "following_error" | "sto" | "clear" | "power_cycle", "device": 2}
    {"inject": "al_error", "device": 2, "code": 26}
                                                slave 2 leaves OP: SAFE-OP + ERROR, AL status code
                                                26 (0x001A, synchronisation error; the default)
    {"inject": "unplug", "device": 3}           the cable before slave 3 pulled: 3.. unreachable
    {"inject": "replug"}
    {"inject": "lose_frames", "frames": 5}     the next 5 frames get no answer
    {"inject": "short_wkc", "device": 2, "frames": 5}
                                                slave 2 leaves its process data alone for 5 frames
    {"status": true}   -> positions (rad), each drive's CiA 402 and AL state, frames seen

It prints `ecatsim: ready, interface IF, control 127.0.0.1:PORT` once the link is up, and
removes the link and the namespace on SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import gc
import logging
import signal
import socket
import threading

from orccadd.config.station import pick_resource
from orccadd.drivers.ethercat.settings import EthercatSettings
from orccadd.drivesim.__main__ import plant_config
from orccadd.drivesim.axis import AxisUnits
from orccadd.ecatsim.drive import DriveSpec
from orccadd.ecatsim.link import LinkError, VethLink
from orccadd.ecatsim.simulator import EcatSimulator
from orccadd.errors import OrccaddError
from orccadd.logsetup import LogSetupError, setup_logging
from orccadd.robot import load_station_config
from orccadd.runtime import sim_control
from orccadd.runtime.rt import realtime_device_process
from orccadd.runtime.threads import ThreadGroup

log = logging.getLogger("orccadd.ecatsim")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m orccadd.ecatsim",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--config", required=True, help="a robot config whose resource is an ethercat402 line")
    ap.add_argument("--resource", default="", help="in a station config: the resource to serve")
    ap.add_argument(
        "--plant", default="", help="a TOML of `sim` settings for the arm (friction, initial pose)"
    )
    ap.add_argument("--netns", default="", help="the namespace to make (default: simulator.netns)")
    ap.add_argument("--peer", default="", help="the slaves' end of the link (default: simulator.peer)")
    ap.add_argument("--control-port", type=int, default=0)
    ap.add_argument("--priority", type=int, default=0, help="SCHED_FIFO priority (0: time-shared)")
    ap.add_argument("--cpu", type=int, default=None, help="run on this core only")
    args = ap.parse_args(argv)
    try:
        setup_logging("orccadd.ecatsim")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    try:
        cfg = pick_resource(load_station_config(args.config), ("ethercat402",), args.resource)
        s = cfg.backend_settings
        if not isinstance(s, EthercatSettings):
            raise OrccaddError(f"{args.config}: resource.backend must be ethercat402 for simulated drives")
        drives = [
            DriveSpec(
                sl.vendor_id,
                sl.product_code,
                sl.revision,
                path,
                AxisUnits(sl.counts_per_rev, sl.gear_ratio, sl.rated_torque_nm),
            )
            for sl, path in zip(s.slaves, s.eds_paths, strict=True)
        ]
        sim = EcatSimulator(plant_config(cfg, args.plant), drives)
        link = VethLink(s.interface, args.peer or s.simulator.peer, args.netns or s.simulator.netns)
    except (OrccaddError, LinkError, OSError, ValueError) as e:
        log.error("%s", e)
        return 1
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    srv = socket.create_server(("127.0.0.1", args.control_port))
    threads = ThreadGroup("ecatsim")
    threads.start(sim_control.serve, srv, sim.inject, sim.status, threads, name="control")
    if args.priority or args.cpu is not None:
        for w in realtime_device_process(args.priority, args.cpu):
            log.warning("%s", w)
    gc.collect()
    gc.freeze()  # dictionaries and the model are long-lived: keep the collector's passes short
    runner = threads.start(sim.run, link, stop.is_set, name="wire")
    port = srv.getsockname()[1]
    print(f"ecatsim: ready, interface {s.interface}, control 127.0.0.1:{port}", flush=True)
    try:
        while not stop.wait(0.2):
            if not runner.is_alive():
                break
    finally:
        stop.set()
        threads.join(5.0)
        srv.close()
        link.close()
    c = sim.chain.counters
    log.info(
        "stopped after %d frames (%d lost on purpose, %d refused)", c.frames, c.frames_lost, sim.bad_frames
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
