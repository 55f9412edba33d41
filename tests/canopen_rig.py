"""A CANopen test rig in separate processes: the virtual bus (or vcan0) and simulated drives."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from orccadd.drivesim.process import DriveSimProcess
from tests.conftest import ROOT, eds
from tools.virtual_can.process import HubProcess, vcan_available

CANOPEN_6AXIS = ROOT / "configs/robots/canopen-6axis.toml"


@dataclass
class Rig:
    config: Path
    hub: HubProcess | None
    drives: DriveSimProcess


def rig_config(tmp: Path, eds_file: str, port: int | None, extra: str = "") -> Path:
    """canopen-6axis.toml on this rig: the bus, the URDF path, every axis on `eds_file`."""
    text = CANOPEN_6AXIS.read_text().replace('urdf = "../urdf/', f'urdf = "{ROOT}/configs/urdf/')
    text = text.replace('eds = "Elmo.dcf"', f'eds = "{eds(eds_file)}"')
    if port is None:  # the kernel's virtual CAN
        text = text.replace('interface = "socketcand"', 'interface = "socketcan"').replace(
            'channel = "can0"', 'channel = "vcan0"'
        )
    else:
        text = text.replace("port = 29536", f"port = {port}")
    text = text.replace('hold_task = "../tasks/', f'hold_task = "{ROOT}/configs/tasks/')
    # this VM stalls processes for up to ~0.3 s now and then: heartbeats every 250 ms (a lost
    # drive is still reported within 3 × 250 ms)
    text = text.replace("heartbeat_ms = 100", "heartbeat_ms = 250")
    # and the drive simulator (a Python process beside the controller on 2 cores) now and then
    # answers nothing for ~0.1-0.15 s while the controller keeps sending SYNCs (measured with its
    # `longest_loop_gap_ms`): a node is silent after 150 SYNCs (0.3 s) here
    text = text.replace("missed_tpdo_periods = 50", "missed_tpdo_periods = 150")
    dirs = ", ".join(f'"{d}"' for d in (ROOT / "configs/missions", ROOT / "tests/daemon/missions", tmp))
    text = text.replace("[daemon]\n", f"[daemon]\nmission_dirs = [{dirs}]\n{extra}\n")
    path = tmp / "canopen-robot.toml"
    path.write_text(text)
    return path


@contextmanager
def canopen_rig(tmp: Path, eds_file: str = "ros_canopen/Elmo.dcf", daemon_extra: str = "") -> Iterator[Rig]:
    # The bus and the drives are hardware on a robot: their timing must not depend on the
    # controller's load. The hub (light) runs at real-time priority below the controller's; the
    # drives (a Pinocchio simulation, ~40 % of a core here) at a high weight but normal policy:
    # at SCHED_FIFO they made the kernel throttle real-time tasks on this 2-core machine.
    hub = None if vcan_available() else HubProcess("--priority", "70")
    try:
        config = rig_config(tmp, eds_file, hub.port if hub else None, daemon_extra)
        drives = DriveSimProcess(config, "--priority", "70")
        try:
            yield Rig(config, hub, drives)
        finally:
            drives.stop()
    finally:
        if hub is not None:
            hub.stop()
