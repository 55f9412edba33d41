"""A simulator (or the virtual CAN hub) as a child process of a test, benchmark or demo.

`ChildProcess` starts `python -m MODULE ARGS`, keeps its log in a file (a pipe nobody reads
would block it once full), waits for its ready line on stdout, and stops it (SIGTERM, then
SIGKILL after `STOP_TIMEOUT_S`). The child gets SIGTERM when its parent dies (Linux
`PR_SET_PDEATHSIG`): a test killed half-way, even by pytest-timeout's `os._exit`, leaves no
simulator running at real-time priority behind it. Standard library only.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import select
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

PR_SET_PDEATHSIG = 1
STOP_TIMEOUT_S = 10.0


def die_with_parent() -> None:
    """In the child, between fork and exec: SIGTERM when the parent dies (only a prctl)."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class ChildProcess:
    """A running child: `ready_line` is the line it printed once serving."""

    def __init__(
        self,
        module: str,
        args: list[str],
        *,
        what: str,
        ready: str,
        env: dict[str, str] | None = None,
        cwd: str | Path | None = None,
        timeout_s: float = 60.0,
    ) -> None:
        self.what = what
        self.log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - lives as long as the process
        self.proc = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            stdout=subprocess.PIPE,
            stderr=self.log,
            text=True,
            cwd=cwd,
            env={**os.environ, **(env or {})},
            preexec_fn=die_with_parent,
        )
        assert self.proc.stdout is not None
        readable, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        self.ready_line = self.proc.stdout.readline() if readable else ""
        if ready not in self.ready_line:
            self.stop()
            raise RuntimeError(f"{what} did not start: {self.ready_line!r} {self.log_text()}")

    def log_text(self) -> str:
        """What the child logged so far."""
        self.log.seek(0)
        return self.log.read()

    def kill(self) -> None:
        """SIGKILL, at once (a device or bus that dies, for fault tests)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            with contextlib.suppress(OSError):
                self.proc.stdout.close()
        return int(self.proc.returncode)
