"""Start and stop `python -m orccadd.ursim` from Python (tests, benchmarks, demos).

Stock ur_rtde reaches a controller on fixed ports (30004, 30003, 29999), so two simulators on
one machine would take each other's ports: `UrSimProcess` holds an exclusive file lock
(`PORTS_LOCK`, in the temporary directory) for as long as its simulator runs, and a second one,
in this process or any other, waits for it (up to `lock_timeout_s`). Pass `lock=False` with
ports of your own (`--rtde-port` ...) to run beside it.

    with UrSimProcess("configs/robots/ur5e-rtde-sim.toml", "--boot", "running") as sim:
        ...  # ur_rtde (or orccadd's ur_rtde backend) on 127.0.0.1
        sim.inject("protective_stop")
        sim.wait_for(lambda st: st["safety_mode"] == "PROTECTIVE_STOP")

ur_rtde's calls block in C++ without releasing the interpreter: a test that may hang in one
needs pytest-timeout's `method="thread"`. Disconnect ur_rtde's clients before the simulator
stops (a client left connected tries to reconnect, and RTDEIOInterface aborts the process).
This module imports only the standard library.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import fcntl
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import IO, Any

PORTS_LOCK = Path(tempfile.gettempdir()) / "orccadd-ursim-ports.lock"
PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In the child, before exec: SIGTERM when the parent dies (Linux), so a test killed
    half-way never leaves a simulator holding UR's ports."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class PortsLock:
    """The machine-wide lock on UR's fixed ports (`flock`, released when closed or on exit)."""

    def __init__(self, timeout_s: float) -> None:
        self._f: IO[bytes] | None = PORTS_LOCK.open("ab")
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(self._f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                if time.monotonic() > deadline:
                    self.release()
                    raise TimeoutError(
                        f"UR's ports stayed taken by another simulator for {timeout_s:g} s ({PORTS_LOCK})"
                    ) from None
                time.sleep(0.1)

    def release(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None


class UrSimProcess:
    """A running simulator: its control channel (`inject`, `status`) and its log."""

    def __init__(
        self,
        config: str | Path,
        *extra: str,
        env: dict[str, str] | None = None,
        timeout_s: float = 60.0,
        lock: bool = True,
        lock_timeout_s: float = 300.0,
    ) -> None:
        self.lock = PortsLock(lock_timeout_s) if lock else None
        cmd = [sys.executable, "-m", "orccadd.ursim", "--config", str(config), *extra]
        # its log goes to a file: a pipe nobody reads while it runs would block it once full
        self.log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - lives as long as the process
        self.proc = subprocess.Popen(
            cmd,
            stdout=subprocess.PIPE,
            stderr=self.log,
            text=True,
            env={**os.environ, **(env or {})},
            preexec_fn=_die_with_parent,  # only prctl: safe between fork and exec
        )
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        line = self.proc.stdout.readline() if ready else ""
        if "ready" not in line:
            self.stop()
            raise RuntimeError(f"UR simulator did not start: {line!r} {self.log_text()}")
        self.control_port = int(line.rsplit(":", 1)[1])

    def __enter__(self) -> UrSimProcess:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def request(self, req: dict[str, Any]) -> dict[str, Any]:
        with (
            socket.create_connection(("127.0.0.1", self.control_port), timeout=10) as s,
            s.makefile("rwb") as f,
        ):
            f.write(json.dumps(req).encode() + b"\n")
            f.flush()
            reply: dict[str, Any] = json.loads(f.readline())
        if not reply.get("ok"):
            raise RuntimeError(f"UR simulator: {reply.get('error')}")
        return reply

    def inject(self, fault: str, **params: Any) -> None:
        """Inject a fault (`orccadd.ursim.faults` lists them and their parameters)."""
        self.request({"inject": fault, **params})

    def status(self) -> dict[str, Any]:
        return self.request({"status": True})

    def wait_for(
        self, predicate: Callable[[dict[str, Any]], bool], timeout_s: float = 10.0
    ) -> dict[str, Any]:
        """Poll `status()` until `predicate` holds; the last status (`TimeoutError` if it never does)."""
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise TimeoutError(f"UR simulator: condition not met in {timeout_s:g} s; status {st}")
            time.sleep(0.02)

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
        if self.proc.stdout is not None:
            with contextlib.suppress(OSError):
                self.proc.stdout.close()
        if self.lock is not None:
            self.lock.release()
            self.lock = None
        return int(self.proc.returncode)
