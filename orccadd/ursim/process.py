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
This module imports only the standard library (and `orccadd.simproc`, which does too).
"""

from __future__ import annotations

import fcntl
import json
import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from orccadd.simproc import ChildProcess

PORTS_LOCK = Path(tempfile.gettempdir()) / "orccadd-ursim-ports.lock"


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


class UrSimProcess(ChildProcess):
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
        try:
            super().__init__(
                "orccadd.ursim",
                ["--config", str(config), *extra],
                what="UR simulator",
                ready="ready",
                env=env,
                timeout_s=timeout_s,
            )
        except BaseException:
            self._release()
            raise
        self.control_port = int(self.ready_line.rsplit(":", 1)[1])

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

    def stop(self) -> int:
        code = super().stop()
        self._release()
        return code

    def _release(self) -> None:
        if self.lock is not None:
            self.lock.release()
            self.lock = None
