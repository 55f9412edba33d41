"""Start and stop `python -m orccadd.drivesim` from Python (tests, benchmarks, demos)."""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

from orccadd.simproc import ChildProcess


class DriveSimProcess(ChildProcess):
    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        args = ["--config", str(config), *extra]
        super().__init__(
            "orccadd.drivesim", args, what="drive simulator", ready="ready", env=env, timeout_s=timeout_s
        )
        self.control_port = int(self.ready_line.rsplit(":", 1)[1])

    def request(self, req: dict[str, Any]) -> dict[str, Any]:
        with (
            socket.create_connection(("127.0.0.1", self.control_port), timeout=10) as s,
            s.makefile("rwb") as f,
        ):
            f.write(json.dumps(req).encode() + b"\n")
            f.flush()
            reply: dict[str, Any] = json.loads(f.readline())
        if not reply.get("ok"):
            raise RuntimeError(f"drive simulator: {reply.get('error')}")
        return reply

    def inject(self, node: int, fault: str, bus: str = "") -> None:
        """`fault` on drive `node` (of `bus`, a channel, when node ids repeat across buses)."""
        self.request({"inject": fault, "node": node, **({"bus": bus} if bus else {})})

    def status(self) -> dict[str, Any]:
        return self.request({"status": True})
