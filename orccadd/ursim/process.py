"""Start and stop `python -m orccadd.ursim` from Python (tests, benchmarks, demos).

Stock ur_rtde reaches a controller on fixed ports (30004, 30003, 29999), so two simulators on
one machine would take each other's ports: `UrSimProcess` holds an exclusive file lock
(in the temporary directory, one per network namespace) for as long as its simulator runs, and a second one,
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
import os
import tempfile
import time
from pathlib import Path
from typing import IO

from orccadd.simproc import SimulatorProcess


def _ports_lock_path() -> Path:
    """The lock file of UR's fixed ports in this network namespace (ports are a namespace's:
    a test process in a namespace of its own, as each pytest worker is, has its own)."""
    try:
        netns = f"-{os.stat('/proc/thread-self/ns/net').st_ino}"
    except OSError:
        netns = ""
    return Path(tempfile.gettempdir()) / f"orccadd-ursim-ports{netns}.lock"


class PortsLock:
    """The machine-wide lock on UR's fixed ports (`flock`, released when closed or on exit)."""

    def __init__(self, timeout_s: float) -> None:
        self.path = _ports_lock_path()
        self._f: IO[bytes] | None = self.path.open("ab")
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(self._f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                if time.monotonic() > deadline:
                    self.release()
                    raise TimeoutError(
                        f"UR's ports stayed taken by another simulator for {timeout_s:g} s ({self.path})"
                    ) from None
                time.sleep(0.1)

    def __enter__(self) -> PortsLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None


class UrSimProcess(SimulatorProcess):
    """The UR controller simulator, holding UR's ports (`PortsLock`) while it runs."""

    module = "orccadd.ursim"
    what = "UR simulator"

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
            super().__init__(config, *extra, env=env, timeout_s=timeout_s)
        except BaseException:
            self._release()
            raise

    def stop(self, timeout_s: float | None = None) -> int:
        code = super().stop(timeout_s)
        self._release()
        return code

    def _release(self) -> None:
        if self.lock is not None:
            self.lock.release()
            self.lock = None
