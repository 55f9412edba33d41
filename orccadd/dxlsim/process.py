"""Start and stop `python -m orccadd.dxlsim` from Python (tests, benchmarks), and talk to its
control socket."""

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


class DxlSimProcess:
    """The simulator as a child process. `port` and `control` are the paths it serves."""

    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        cmd = [sys.executable, "-m", "orccadd.dxlsim", "--config", str(config), *extra]
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
            raise RuntimeError(f"servo simulator did not start: {line!r} {self.log_text()}")
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

    def log_text(self) -> str:
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
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return int(self.proc.returncode)
