"""Start and stop a virtual CAN hub from Python (tests, benchmarks), or pick `vcan0` if present."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
HOST = "127.0.0.1"


def vcan_available(iface: str = "vcan0") -> bool:
    """True where the kernel has SocketCAN and `iface` exists (tools/virtual_can/setup_vcan.sh)."""
    if not hasattr(socket, "AF_CAN") or not Path(f"/sys/class/net/{iface}").is_dir():
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return True


class HubProcess:
    """`python -m tools.virtual_can.hub --port 0` as a child; `port` once it listens."""

    def __init__(self, *extra: str, startup_timeout_s: float = 30.0) -> None:
        cmd = [sys.executable, "-m", "tools.virtual_can.hub", "--port", "0", *extra]
        # its log goes to a file: a pipe nobody reads while it runs would block it once full
        self.log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - lives as long as the process
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=self.log, text=True)
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], startup_timeout_s)
        line = self.proc.stdout.readline() if ready else ""
        if "listening on" not in line:
            self.stop()
            raise RuntimeError(f"virtual CAN hub did not start: {line!r} {self.stderr_text()}")
        self.port = int(line.rsplit(":", 1)[1])

    def bus_kwargs(self, channel: str = "can0") -> dict[str, Any]:
        """Keyword arguments of `can.Bus` for this hub."""
        return {"interface": "socketcand", "host": HOST, "port": self.port, "channel": channel}

    def kill(self) -> None:
        """Kill the hub abruptly (a bus failure, for fault tests)."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)

    def stderr_text(self) -> str:
        """What the hub logged so far."""
        self.log.seek(0)
        return self.log.read()

    def __enter__(self) -> HubProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
