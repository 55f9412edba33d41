"""The systemd unit is valid and sandboxed (yet leaves real time its due), and orccadd speaks
sd_notify: READY, WATCHDOG while healthy, STOPPING."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from orccadd.config.robot import DaemonConfig
from orccadd.ctl.client import DEFAULT_SOCKET, Client, ClientError
from tests.daemon.conftest import ROOT, robot_config

UNIT = ROOT / "packaging/systemd/orccadd.service"
CAN_UNIT = ROOT / "packaging/systemd/orccadd-can@.service"
EXEC = "/opt/orccadd/venv/bin/orccadd"  # where docs/install.md installs it
MAX_EXPOSURE = 5.0  # `systemd-analyze security`: 0 safest, 10 unsandboxed root (9.6 before issue 18)
needs_analyze = pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze missing")


def settings(text: str, key: str) -> list[str]:
    """The values of every `key=` line of a unit file."""
    return [ln.split("=", 1)[1].strip() for ln in text.splitlines() if ln.startswith(f"{key}=")]


def unit_copy(tmp_path: Path) -> Path:
    """The unit, its ExecStart pointed at a real file (systemd-analyze checks that it exists)."""
    exe = tmp_path / "orccadd"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    text = UNIT.read_text()
    assert settings(text, "ExecStart")[0].startswith(EXEC + " ")
    unit = tmp_path / "orccadd.service"
    unit.write_text(text.replace(EXEC, str(exe)))
    return unit


def verify(unit: Path) -> None:
    p = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=60)
    problems = [ln for ln in p.stderr.splitlines() if unit.name in ln]
    assert p.returncode == 0 and not problems, p.stderr


@needs_analyze
def test_unit_file_verifies(tmp_path: Path) -> None:
    verify(unit_copy(tmp_path))
    text = UNIT.read_text()
    for key in ("Type=notify", "WatchdogSec=", "LimitRTPRIO=", "LimitMEMLOCK=infinity", "Restart=on-failure"):
        assert key in text


@needs_analyze
def test_can_link_unit_verifies(tmp_path: Path) -> None:
    unit = tmp_path / "orccadd-can@can0.service"
    unit.write_text(CAN_UNIT.read_text())
    verify(unit)


@needs_analyze
def test_unit_is_sandboxed(tmp_path: Path) -> None:
    unit = unit_copy(tmp_path)
    cmd = ["systemd-analyze", "security", "--offline=true", f"--threshold={MAX_EXPOSURE * 10:g}", str(unit)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    if "--offline" in p.stderr and "unrecognized" in p.stderr:  # systemd < 250
        pytest.skip("systemd-analyze security has no --offline")
    m = re.search(r"Overall exposure level for orccadd\.service: (\d+(?:\.\d+)?)", p.stdout)
    assert m, p.stdout + p.stderr
    assert float(m.group(1)) <= MAX_EXPOSURE, p.stdout
    assert p.returncode == 0, p.stdout + p.stderr  # --threshold: the tool's own verdict agrees


def syscalls(*names: str) -> set[str]:
    """System calls named, with `@groups` expanded (as `systemd-analyze syscall-filter` lists them)."""
    out: set[str] = set()
    for name in names:
        if not name.startswith("@"):
            out.add(name)
            continue
        cmd = ["systemd-analyze", "syscall-filter", name]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert p.returncode == 0, p.stderr
        members = [ln.strip() for ln in p.stdout.splitlines()[1:]]
        out |= syscalls(*(m for m in members if m and not m.startswith("#")))
    return out


@needs_analyze
def test_sandbox_leaves_real_time_its_due() -> None:
    """What the loop needs stays allowed: SCHED_FIFO up to the configured priorities, locked
    memory, the PM QoS device, the command socket where clients look for it."""
    text = UNIT.read_text()
    cfg = DaemonConfig()
    assert int(settings(text, "LimitRTPRIO")[0]) >= max(cfg.automaton_priority, cfg.control_priority)
    assert settings(text, "LimitMEMLOCK") == ["infinity"]
    assert settings(text, "RestrictRealtime") in ([], ["no"])
    assert "/dev/cpu_dma_latency rw" in settings(text, "DeviceAllow")
    allowed = set()
    for value in settings(text, "SystemCallFilter"):
        assert not value.startswith("~"), "a deny list would have to be checked against these calls"
        allowed |= syscalls(*value.split())
    assert {"sched_setscheduler", "sched_setaffinity", "mlockall", "setpriority"} <= allowed
    assert "AF_UNIX" in settings(text, "RestrictAddressFamilies")[0].split()
    assert settings(text, "User") != ["root"]
    argv = settings(text, "ExecStart")[0].split()
    assert argv[argv.index("--socket") + 1] == cfg.socket == DEFAULT_SOCKET
    assert Path(cfg.socket).parent == Path("/run") / settings(text, "RuntimeDirectory")[0]


def test_files_the_unit_names_are_shipped() -> None:
    for rel in set(re.findall(r"packaging/\S+?\.(?:rules|service)", UNIT.read_text())):
        assert (ROOT / rel).is_file(), rel


def test_sd_notify_messages(tmp_path: Path) -> None:
    addr = str(tmp_path / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(addr)
    sock.settimeout(60)
    env = {**os.environ, "NOTIFY_SOCKET": addr, "WATCHDOG_USEC": "400000"}
    cmd = [
        sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(robot_config(tmp_path)),
        "--socket", str(tmp_path / "run/orccadd.sock"), "--no-command-daemon",
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    got: list[str] = []
    try:
        end = time.monotonic() + 60
        while time.monotonic() < end and sum(m == "WATCHDOG=1" for m in got) < 3:
            got.extend(sock.recv(4096).decode().split("\n"))
        assert got[0] == "READY=1" and any(m.startswith("STATUS=") for m in got)
        assert sum(m == "WATCHDOG=1" for m in got) >= 3
        proc.terminate()
        assert proc.wait(timeout=20) == 0
        sock.settimeout(1)
        try:  # until STOPPING, within the second it was given to come (it was sent before the exit)
            while "STOPPING=1" not in got:
                got.extend(sock.recv(4096).decode().split("\n"))
        except TimeoutError:
            pass
        assert "STOPPING=1" in got
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        sock.close()


def test_watchdog_pings_stop_while_the_control_loop_stalls(tmp_path: Path) -> None:
    addr = str(tmp_path / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(addr)
    sock.settimeout(60)
    env = {**os.environ, "NOTIFY_SOCKET": addr, "WATCHDOG_USEC": "400000"}  # a ping every 0.1 s
    sock_path = str(tmp_path / "run/orccadd.sock")
    cmd = [
        sys.executable, "-m", "orccadd.daemon.rtproc", "--config", str(robot_config(tmp_path)),
        "--socket", sock_path, "--allow-fault-injection",
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    pings: list[float] = []

    def collect(until_s: float, done: Callable[[], bool] = lambda: False) -> None:
        while time.monotonic() < until_s and not done():
            try:
                msgs = sock.recv(4096).decode().split("\n")
            except TimeoutError:
                continue
            pings.extend(time.monotonic() for m in msgs if m == "WATCHDOG=1")

    try:
        sock.settimeout(0.05)
        end = time.monotonic() + 60
        while time.monotonic() < end and len(pings) < 3:
            collect(time.monotonic() + 0.2)
        assert len(pings) >= 3
        while True:  # the command daemon comes up after READY
            try:
                with Client(sock_path) as c:
                    c.call("inject", fault="overrun", ticks=1, extra_ms=2500.0)  # one tick stalls 2.5 s
                break
            except (ClientError, OSError):
                assert time.monotonic() < end
                time.sleep(0.2)
        t_inject = time.monotonic()

        def gaps_s() -> np.ndarray:
            return np.diff([t for t in pings if t > t_inject - 1.0])

        def paused_and_resumed() -> bool:  # what the asserts below check: more pings change neither
            gaps = gaps_s()
            return bool(gaps.size and gaps.max() > 1.5 and pings[-1] > t_inject + 3.0)

        collect(t_inject + 5.0, paused_and_resumed)  # the 5 s: the 2.5 s stall and time to resume
        gaps = gaps_s()
        # the heartbeat goes stale after watchdog_stale_periods (50 × 2 ms): pings stop for most
        # of the stall, and come back once the loop ticks again
        assert gaps.size and gaps.max() > 1.5, f"pings never paused: gaps {gaps}"
        assert pings[-1] > t_inject + 3.0, "pings did not resume after the stall"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        sock.close()
