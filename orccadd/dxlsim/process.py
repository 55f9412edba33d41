"""Start and stop `python -m orccadd.dxlsim` from Python (tests, benchmarks), and talk to its
control socket."""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

from orccadd.simproc import ChildProcess


class DxlSimProcess(ChildProcess):
    """The simulator as a child process. `port` and `control` are the paths it serves."""

    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        args = ["--config", str(config), *extra]
        super().__init__(
            "orccadd.dxlsim", args, what="servo simulator", ready="ready", env=env, timeout_s=timeout_s
        )
        line = self.ready_line
        fields = dict(part.strip().split(" ", 1) for part in line.split(":", 1)[1].split(",")[1:])
        self.port = fields["port"]
        self.control = fields["control"]

    def request(self, req: dict[str, Any], timeout_s: float = 10.0) -> dict[str, Any]:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(timeout_s)
            s.connect(self.control)
            with s.makefile("rwb") as f:
                f.write(json.dumps(req).encode() + b"\n")
                f.flush()
                reply: dict[str, Any] = json.loads(f.readline())
        if not reply.get("ok"):
            raise RuntimeError(f"servo simulator: {reply.get('error')}")
        return reply

    def inject(self, fault: str, dxl_id: int | None = None, rate: float | None = None) -> None:
        req: dict[str, Any] = {"inject": fault}
        if dxl_id is not None:
            req["id"] = dxl_id
        if rate is not None:
            req["rate"] = rate
        self.request(req)

    def status(self) -> dict[str, Any]:
        return self.request({"status": True})
