"""A real orccadd (real-time process + command daemon + plant process) per test, on a temporary socket."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from orccadd.ctl.client import Client, ClientError
from orccadd.daemon.machine import Machine
from orccadd.robot import create_resource, load_robot_config, with_backend
from orccadd.runtime import WallClock
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


class Daemon:
    def __init__(self, proc: subprocess.Popen[bytes], socket: str, log: Path) -> None:
        self.proc = proc
        self.socket = socket
        self.log = log

    def client(self) -> Client:
        # a load compiles in a process of its own at normal priority: on a busy machine, beside a
        # real-time loop and simulators, that takes far longer than the client's default 10 s
        return Client(self.socket, timeout_s=60.0)

    def call(self, cmd: str, **args: object) -> object:
        with self.client() as c:
            return c.call(cmd, **args)

    def reply(self, cmd: str, **args: object) -> dict[str, object]:
        with self.client() as c:
            return c.reply(cmd, **args)

    def status(self) -> dict[str, object]:
        s = self.call("status")
        assert isinstance(s, dict)
        return s

    def wait(self, pred: Callable[[dict[str, object]], bool], timeout_s: float = 30.0) -> dict[str, object]:
        end = time.monotonic() + timeout_s
        while True:
            s = self.status()
            if pred(s):
                return s
            if time.monotonic() > end:
                raise AssertionError(f"timed out; last status: {s}\nlog:\n{self.log.read_text()}")
            time.sleep(0.05)

    def ctl(self, *argv: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
        env = {**os.environ, "ORCCADD_SOCKET": self.socket}
        return subprocess.run(
            [sys.executable, "-m", "orccadd.cli", *argv],
            capture_output=True,
            text=True,
            env=env,
            timeout=timeout_s,
        )

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                return self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)


def start_daemon(tmp: Path, *extra: str, daemon_cfg: str = "") -> Daemon:
    return start_daemon_with(tmp, robot_config(tmp, daemon_cfg), *extra)


def start_daemon_with(tmp: Path, config: Path, *extra: str, own_group: bool = False) -> Daemon:
    """orccadd on `config`, a socket in `tmp`, fault injection allowed; up and answering.
    `own_group`: in a process group of its own, as a shell job or a systemd service is."""
    sock = str(tmp / "run" / "orccadd.sock")
    log = tmp / "orccadd.log"
    cmd = [
        sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(config),
        "--socket", sock, "--allow-fault-injection", *extra,
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=own_group)
    d = Daemon(proc, sock, log)
    end = time.monotonic() + 60
    while True:
        if proc.poll() is not None:
            raise AssertionError(f"orccadd exited ({proc.returncode}):\n{log.read_text()}")
        try:
            d.call("ping")
            return d
        except (ClientError, OSError):
            if time.monotonic() > end:
                d.stop()
                raise AssertionError(f"orccadd did not come up:\n{log.read_text()}") from None
            time.sleep(0.02)


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[Daemon]:
    d = start_daemon(tmp_path)
    try:
        yield d
    finally:
        d.stop()


@pytest.fixture
def machine(tmp_path: Path) -> Iterator[Machine]:
    """The real-time process's machine on sim-ur5e in this process, without its threads: a
    test ticks the loop (`loop.executor.run`) and plays the automaton thread itself. Missions
    load from `tmp_path` too."""
    cfg = with_backend(load_robot_config(ROBOT), "sim")
    dirs = (*cfg.daemon.mission_dirs, str(tmp_path))
    cfg = replace(cfg, daemon=replace(cfg.daemon, mission_dirs=dirs))
    res = create_resource(cfg)
    res.configure()
    res.activate(CommandMode.TORQUE)
    tel = TelemetryBlock.create(Layout(cfg.dof, 8000, 1000), cfg.control_period_s)
    r, w = os.pipe2(os.O_NONBLOCK)
    m = Machine(cfg, res, WallClock(), tel, w)
    try:
        yield m
    finally:
        tel.close()
        res.shutdown()
        os.close(r)
        os.close(w)
