"""A CANopen test rig in separate processes: the virtual bus (or vcan0) and simulated drives,
plus a recorder of every frame on that bus."""

from __future__ import annotations

import bisect
import re
import struct
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import can

from orccadd.drivesim.process import DriveSimProcess
from orccadd.drivesim.socketcand import QueuedSocketcandBus
from orccadd.vcan.process import HOST, HubProcess, vcan_available
from tests.conftest import ROOT, eds

CANOPEN_6AXIS = ROOT / "configs/robots/canopen-6axis.toml"
CANOPEN_2BUS = ROOT / "configs/robots/canopen-2bus.toml"  # six axes on two buses, 1 kHz
BUS_PORTS = (29536, 29537)  # the shipped configs' socketcand ports, one per bus (a hub each here)
BUS_CHANNELS = ("can0", "can1")
ELMO = "ros_canopen/Elmo.dcf"
CONSUMING_ELMO = "consuming Elmo"  # `consuming_elmo`: the rig's default drives


@dataclass
class Rig:
    config: Path
    hub: HubProcess | None  # the first bus's
    drives: DriveSimProcess
    hubs: tuple[HubProcess, ...] = ()  # one per bus (none on vcan)


def edit_dcf(source: Path, dest: Path, edits: dict[str, dict[str, str]]) -> Path:
    """`source` with keys of its sections replaced (`{"1016sub0": {"DefaultValue": "0"}}`)."""
    text = source.read_text(errors="replace")
    for section, keys in edits.items():
        head = re.search(rf"^\[{section}\]\s*$", text, re.MULTILINE | re.IGNORECASE)
        assert head is not None, f"{source.name} has no [{section}]"
        end = text.find("\n[", head.end())
        end = len(text) if end < 0 else end
        body = text[head.end() : end]
        for key, value in keys.items():
            body, n = re.subn(rf"^{key}=.*$", f"{key}={value}", body, flags=re.MULTILINE)
            assert n == 1, f"{source.name} [{section}] has no {key}"
        text = text[: head.end()] + body + text[end:]
    dest.write_text(text)
    return dest


def consuming_elmo(tmp: Path) -> Path:
    """Elmo.dcf whose heartbeat consumer entries (0x1016) take a producer id: the file caps them
    at 0xFFFF (only a time), a flaw of the file, not of the drive. With it the simulated drives
    watch the controller's heartbeat, as real Elmo drives do."""
    caps = {f"1016sub{sub}": {"HighLimit": "0x007FFFFF"} for sub in (1, 2)}
    return edit_dcf(eds(ELMO), tmp / "Elmo-consuming.dcf", caps)


def bus_count(robot: Path) -> int:
    """How many buses a shipped canopen config has (its socketcand ports)."""
    text = robot.read_text()
    return sum(1 for port in BUS_PORTS if f"port = {port}" in text)


def rig_config(
    tmp: Path,
    eds_file: str | Path,
    port: int | list[int] | None,
    extra: str = "",
    settings_extra: str = "",
    robot: Path = CANOPEN_6AXIS,
    period_s: float | None = None,
) -> Path:
    """`robot` (canopen-6axis.toml, or canopen-2bus.toml) on this rig: the buses (a hub's port
    each, or None: vcan), the URDF path, every axis on `eds_file` (a path, or a name under
    testdata/eds/), `settings_extra` lines in [resource.settings], `period_s` for the robot's
    control period if given."""
    path = eds_file if isinstance(eds_file, Path) else eds(eds_file)
    text = robot.read_text().replace('urdf = "../urdf/', f'urdf = "{ROOT}/configs/urdf/')
    text = re.sub(r'(?m)^eds = "[^"]*"', f'eds = "{path}"', text)
    if port is None:  # the kernel's virtual CAN
        text = text.replace('interface = "socketcand"', 'interface = "socketcan"')
        for channel in BUS_CHANNELS:
            text = text.replace(f'"{channel}"', f'"v{channel}"')
    else:
        for default, hub_port in zip(BUS_PORTS, [port] if isinstance(port, int) else port, strict=False):
            text = text.replace(f"port = {default}", f"port = {hub_port}")
    text = text.replace('hold_task = "../tasks/', f'hold_task = "{ROOT}/configs/tasks/')
    # this VM stalls processes for up to ~0.3 s now and then (more with a busy process beside the
    # suite: a CI run saw every drive lose a test's heartbeat, 3 × 100 ms): heartbeats every 250 ms
    # (a lost drive is still reported within 3 × 250 ms), ours every 200 ms (the drives that watch
    # it fault after 3 × 200 ms of silence)
    text = text.replace("heartbeat_ms = 100", "heartbeat_ms = 250")
    text = text.replace("controller_heartbeat_ms = 50", "controller_heartbeat_ms = 200")
    # and the drive simulator (a Python process beside the controller on 2 cores) now and then
    # answers nothing for ~0.1-0.15 s while the controller keeps sending SYNCs (measured with its
    # `longest_loop_gap_ms`): a node is silent after 150 SYNCs (0.3 s) here
    # (0.3 s whatever the period: 150 at 500 Hz, 300 at 1 kHz)
    period = re.search(r"^control_period_s = ([0-9.e-]+)", text, re.MULTILINE)
    assert period is not None, robot
    if period_s is None:
        period_s = float(period.group(1))
    text = text.replace(period.group(0), f"control_period_s = {period_s!r}")
    text = re.sub(r"missed_tpdo_periods = \d+", f"missed_tpdo_periods = {round(0.3 / period_s)}", text)
    text = text.replace("[resource.settings]\n", f"[resource.settings]\n{settings_extra}\n")
    dirs = ", ".join(f'"{d}"' for d in (ROOT / "configs/missions", ROOT / "tests/daemon/missions", tmp))
    tasks = ROOT / "configs/tasks"
    text = text.replace(
        "[daemon]\n", f'[daemon]\nmission_dirs = [{dirs}]\ntask_dirs = ["{tasks}"]\n{extra}\n'
    )
    path = tmp / "canopen-robot.toml"
    path.write_text(text)
    return path


@contextmanager
def canopen_rig(
    tmp: Path,
    eds_file: str | Path = CONSUMING_ELMO,
    daemon_extra: str = "",
    settings_extra: str = "",
    drivesim_args: tuple[str, ...] = (),
    robot: Path = CANOPEN_6AXIS,
    period_s: float | None = None,
) -> Iterator[Rig]:
    """The bus (a hub per bus of `robot`) and six simulated drives (strict, see
    `orccadd.drivesim.axis.Strictness`; relaxed by `drivesim_args` such as `--lenient
    heartbeat_consumer`), every one described by `eds_file` (by default Elmo drives that watch
    our heartbeat). Every process it starts is stopped on exit."""
    # The bus and the drives are hardware on a robot: their timing must not depend on the
    # controller's load nor on anything else the machine runs. The hub and the drives (every
    # thread of each) run at real-time priority below the controller's.
    description = consuming_elmo(tmp) if eds_file == CONSUMING_ELMO else eds_file
    n = bus_count(robot)
    vcan = all(vcan_available(f"v{c}") for c in BUS_CHANNELS[:n])
    hubs: list[HubProcess] = []
    try:
        if not vcan:
            for _ in range(n):
                hubs.append(HubProcess("--priority", "70"))
        ports = [h.port for h in hubs] if hubs else None
        config = rig_config(tmp, description, ports, daemon_extra, settings_extra, robot, period_s)
        drives = DriveSimProcess(config, "--priority", "70", *drivesim_args)
        try:
            yield Rig(config, hubs[0] if hubs else None, drives, tuple(hubs))
        finally:
            drives.stop()
    finally:
        for hub in hubs:
            hub.stop()


class BusRecorder:
    """Every frame on the rig's bus, stamped by the bus itself (the hub as it forwards a frame,
    or the kernel), kept by a thread of the test process from `start` to `stop`."""

    def __init__(self, rig: Rig, bus: int = 0) -> None:
        self.bus: can.BusABC = (
            QueuedSocketcandBus(BUS_CHANNELS[bus], HOST, rig.hubs[bus].port)
            if rig.hubs
            else can.Bus(interface="socketcan", channel=f"v{BUS_CHANNELS[bus]}")
        )
        self.frames: list[can.Message] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._record, name="bus-recorder", daemon=True)

    def _record(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is not None:
                self.frames.append(msg)

    def __enter__(self) -> BusRecorder:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.bus.shutdown()


# ---- reading a recording -------------------------------------------------------------------------
COB_SYNC, COB_HEARTBEAT_OURS = 0x080, 0x77F


def receive(bus: can.BusABC, n: int, timeout_s: float = 10.0) -> list[can.Message]:
    """Up to `n` frames from `bus`, waiting `timeout_s` at most for them."""
    got: list[can.Message] = []
    end = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < end:
        m = bus.recv(0.2)
        if m is not None:
            got.append(m)
    return got


def until(frames: list[can.Message], end_s: float) -> list[can.Message]:
    """The frames stamped before `end_s` (wall clock, as the bus stamps them)."""
    return [m for m in frames if m.timestamp < end_s]


def enable_to_sync_gaps_s(frames: list[can.Message]) -> list[float]:
    """For every RPDO that carries Enable Operation (controlword 0x0F, RPDO1 on 0x200 + node id),
    how long until the next SYNC (those with no SYNC after them in the recording are left out)."""
    syncs = [m.timestamp for m in frames if m.arbitration_id == COB_SYNC]
    gaps = []
    for m in frames:
        if 0x201 <= m.arbitration_id <= 0x27F and len(m.data) >= 2 and m.data[0] & 0x8F == 0x0F:
            k = bisect.bisect_right(syncs, m.timestamp)
            if k < len(syncs):
                gaps.append(syncs[k] - m.timestamp)
    return gaps


def emcy_errors(frames: list[can.Message]) -> list[tuple[int, int]]:
    """(node id, error code) of every EMCY that reports an error (not an error reset)."""
    return [
        (m.arbitration_id - 0x80, int.from_bytes(m.data[:2], "little"))
        for m in frames
        if 0x81 <= m.arbitration_id <= 0xFF and len(m.data) >= 2 and m.data[:2] != b"\0\0"
    ]


def sdo_downloads(frames: list[can.Message]) -> list[tuple[int, int, int, int]]:
    """(node id, index, sub, value) of every expedited SDO download request, in bus order."""
    return [
        (
            m.arbitration_id - 0x600,
            *struct.unpack_from("<HB", m.data, 1),
            int.from_bytes(m.data[4:8], "little"),
        )
        for m in frames
        if 0x601 <= m.arbitration_id <= 0x67F and len(m.data) == 8 and m.data[0] & 0xE2 == 0x22
    ]


def nodes_enabled(frames: list[can.Message]) -> set[int]:
    """The nodes whose TPDO1 (statusword first, on 0x180 + node id) reported OPERATION ENABLED."""
    return {
        m.arbitration_id - 0x180
        for m in frames
        if 0x181 <= m.arbitration_id <= 0x1FF and len(m.data) >= 2 and m.data[0] & 0x6F == 0x27
    }
