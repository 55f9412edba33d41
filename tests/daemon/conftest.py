"""A real orccadd (real-time process + command daemon + plant process) per test, on a temporary socket."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import cast

import numpy as np
import pytest

from orccadd.config.robot import RobotConfig
from orccadd.config.station import StationConfig
from orccadd.daemon.machine import Machine
from orccadd.daemon.replies import Pending
from orccadd.launch import DaemonProcess
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.runtime import SimClock
from orccadd.runtime.clock import Clock
from orccadd.types import CommandMode
from orccadd.wire.schema import Layout
from orccadd.wire.telemetry import TelemetryBlock

ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "configs/robots/sim-ur5e.toml"
MISSIONS = Path(__file__).resolve().parent / "missions"


def mission_dirs(tmp: Path) -> str:
    """The mission directories a test daemon may load from (TOML list items)."""
    dirs = [ROOT / "configs/missions", ROOT / "tests/daemon/missions", ROOT / "tests/automaton/missions", tmp]
    return ", ".join(f'"{d}"' for d in dirs)


def robot_config(tmp: Path, daemon: str = "") -> Path:
    """sim-ur5e with a [daemon] section, written next to the test (paths made absolute)."""
    text = ROBOT.read_text().replace(
        'urdf = "../urdf/ur5e.urdf"', f'urdf = "{ROOT / "configs/urdf/ur5e.urdf"}"'
    )
    text = text.replace(
        "\n[daemon]\n",
        f'\n[daemon]\nhold_task = "{ROOT / "configs/tasks/hold.toml"}"\n'
        f'task_dirs = ["{ROOT / "configs/tasks"}"]\n{daemon}\n',
    )
    text = text.replace("mission_dirs = [", f"mission_dirs = [{mission_dirs(tmp)}, ")
    path = tmp / "robot.toml"
    path.write_text(text)
    return path


Daemon = DaemonProcess  # the one helper the demo and the benchmarks use too


def start_daemon(tmp: Path, *extra: str, daemon_cfg: str = "") -> Daemon:
    return start_daemon_with(tmp, robot_config(tmp, daemon_cfg), *extra)


def start_daemon_with(tmp: Path, config: Path, *extra: str, own_group: bool = False) -> Daemon:
    """orccadd on `config`, a socket in `tmp`, fault injection allowed; up and answering.
    `own_group`: in a process group of its own, as a shell job or a systemd service is."""
    sock = tmp / "run" / "orccadd.sock"
    return DaemonProcess(
        config, sock, tmp / "orccadd.log", "--allow-fault-injection", *extra, new_session=own_group,
        up_timeout_s=60.0,
    )  # fmt: skip


def station_copy(station: Path, tmp: Path, daemon_lines: str = "") -> Path:
    """A copy of the station config `station` in `tmp` (its resources' configs named by absolute paths,
    so that they still name the shipped files), with `daemon_lines` added to its [daemon] table."""
    text = station.read_text().replace('config = "', f'config = "{station.parent}/')
    if daemon_lines:
        head, found, rest = text.partition("\n[daemon]\n")
        text = f"{head}\n[daemon]\n{daemon_lines}\n{rest}" if found else f"{text}\n[daemon]\n{daemon_lines}\n"
    out = tmp / station.name
    out.write_text(text)
    return out


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[Daemon]:
    d = start_daemon(tmp_path)
    try:
        yield d
    finally:
        d.stop()


@contextmanager
def machine_on(cfg: RobotConfig, mode: CommandMode, clock: Clock) -> Iterator[Machine]:
    """The real-time process's machine on `cfg`'s (simulated) resource in this process, without
    its threads, the resource active in `mode`; released at the end."""
    res = create_resource(cfg)
    res.configure()
    res.activate(mode)
    extra = sum(g.size for g in res.description.signals)  # the resource's signals in each tick
    tel = TelemetryBlock.create(Layout(cfg.dof, 8000, 1, extra), cfg.control_period_s)
    block = TelemetryBlock.create(Layout(0, 1, 1000), cfg.control_period_s)  # the status, the trace
    r, w = os.pipe2(os.O_NONBLOCK)
    m = Machine(StationConfig.of(cfg), [res], [clock], [tel], block, w)
    try:
        yield m
    finally:
        m.join_units(5.0)
        tel.close()
        block.close()
        res.shutdown()
        os.close(r)
        os.close(w)


@pytest.fixture
def machine(tmp_path: Path) -> Iterator[Machine]:
    """The machine on sim-ur5e (`machine_on`): a test ticks the loop (`loop.executor.run`) and
    plays the automaton thread itself, in simulated time (`SimClock`: a tick is a period of the
    arm's whatever the machine's load). Missions load from `tmp_path` too."""
    cfg = with_backend(load_robot_config(ROBOT), "sim")
    dirs = (*cfg.daemon.mission_dirs, str(tmp_path))
    cfg = replace(cfg, daemon=replace(cfg.daemon, mission_dirs=dirs))
    with machine_on(cfg, CommandMode.TORQUE, SimClock()) as m:
        yield m


def load_in(machine: Machine, path: Path, timeout_s: float = 60.0) -> object:
    """`load` on an in-process machine (the automaton thread's part played here), its reply once
    the compile child answered; `CommandError` if refused."""
    with machine.reactor.held():
        reply = machine.command("load", {"path": str(path)})
    deadline = time.monotonic() + timeout_s
    while isinstance(reply, Pending):
        assert time.monotonic() < deadline, "the load did not end"
        time.sleep(0.05)
        reply = reply.poll() or (reply.expire() if time.monotonic_ns() > reply.deadline_ns else reply)
    return reply


def moving(s: dict[str, object], above_rad_s: float = 0.1) -> bool:
    """A status in which some joint moves faster than `above_rad_s`."""
    joints = cast(list[dict[str, float]], s["joints"])
    return max(abs(j["dq_rad_s"]) for j in joints) > above_rad_s


def log_rows(csv: Path) -> np.ndarray:
    """A full-rate log's rows (`orccadctl log stop -o`: comment lines, a header, the values)."""
    lines = csv.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return np.loadtxt(lines[header + 1 :], delimiter=",", ndmin=2)
