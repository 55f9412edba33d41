"""Start and stop `python -m orccadd.drivesim` from Python (tests, benchmarks, demos)."""

from __future__ import annotations

import json
import os
import select
import socket
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any


class DriveSimProcess:
    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        cmd = [sys.executable, "-m", "orccadd.drivesim", "--config", str(config), *extra]
        # its log goes to a file: a pipe nobody reads while it runs would block it once full
        self.log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - lives as long as the process
        self.proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=self.log, text=True, env={**os.environ, **(env or {})}
        )
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        line = self.proc.stdout.readline() if ready else ""
        if "ready" not in line:
            self.stop()
            raise RuntimeError(f"drive simulator did not start: {line!r} {self.log_text()}")
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

    def log_text(self) -> str:
        """What the simulator logged so far."""
        self.log.seek(0)
        return self.log.read()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)
