"""The systemd unit is valid, and orccadd speaks sd_notify: READY, WATCHDOG while healthy, STOPPING."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from orccadd.ctl.client import Client, ClientError
from tests.daemon.conftest import ROOT, robot_config

UNIT = ROOT / "packaging/systemd/orccadd.service"


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze missing")
def test_unit_file_verifies(tmp_path: Path) -> None:
    # systemd-analyze checks that ExecStart exists: point it at a real file in a copy of the unit
    exe = tmp_path / "orccadd"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    unit = tmp_path / "orccadd.service"
    unit.write_text(UNIT.read_text().replace("/opt/orccadd/.venv/bin/orccadd", str(exe)))
    p = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=60)
    problems = [ln for ln in p.stderr.splitlines() if "orccadd.service" in ln]
    assert p.returncode == 0 and not problems, p.stderr
    text = UNIT.read_text()
    for key in ("Type=notify", "WatchdogSec=", "LimitRTPRIO=", "LimitMEMLOCK=infinity", "Restart=on-failure"):
        assert key in text


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
        try:
            while True:
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

    def collect(until_s: float) -> None:
        while time.monotonic() < until_s:
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
        collect(t_inject + 5.0)
        gaps = np.diff([t for t in pings if t > t_inject - 1.0])
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
