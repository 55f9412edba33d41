"""Start and stop `python -m orccadd.drivesim` from Python (tests, benchmarks, demos)."""

from __future__ import annotations

import json
import os
import select
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any


class DriveSimProcess:
    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        cmd = [sys.executable, "-m", "orccadd.drivesim", "--config", str(config), *extra]
        self.proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})}
        )
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        line = self.proc.stdout.readline() if ready else ""
        if "ready" not in line:
            self.stop()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"drive simulator did not start: {line!r} {err}")
        self.control_port = int(line.rsplit(":", 1)[1])

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

    def inject(self, node: int, fault: str) -> None:
        self.request({"inject": fault, "node": node})

    def status(self) -> dict[str, Any]:
        return self.request({"status": True})

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)
