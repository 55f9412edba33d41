"""Start and stop a virtual CAN hub from Python (tests, benchmarks), or pick `vcan0` if present."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

from orccadd.simproc import ChildProcess

ROOT = Path(__file__).resolve().parents[2]
HOST = "127.0.0.1"


def vcan_available(iface: str = "vcan0") -> bool:
    """True where the kernel has SocketCAN and `iface` exists (tools/setup_vcan.sh)."""
    if not hasattr(socket, "AF_CAN") or not Path(f"/sys/class/net/{iface}").is_dir():
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return True


class HubProcess(ChildProcess):
    """`python -m orccadd.vcan --port 0` as a child; `port` once it listens."""

    def __init__(self, *extra: str, startup_timeout_s: float = 30.0) -> None:
        args = ["--port", "0", *extra]
        super().__init__(
            "orccadd.vcan",
            args,
            what="virtual CAN hub",
            ready="listening on",
            cwd=ROOT,
            timeout_s=startup_timeout_s,
        )
        self.port = int(self.ready_line.rsplit(":", 1)[1])

    def bus_kwargs(self, channel: str = "can0") -> dict[str, Any]:
        """Keyword arguments of `can.Bus` for this hub."""
        return {"interface": "socketcand", "host": HOST, "port": self.port, "channel": channel}

    def stderr_text(self) -> str:
        """What the hub logged so far."""
        return self.log_text()
