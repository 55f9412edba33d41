"""`DaemonProcess`: orccadd (the real-time process and its command daemon) in a child process on
a socket of its own, up and answering once constructed, stopped as a service manager stops it
(SIGTERM: a safe stop first, then the hardware released; SIGKILL after a timeout). One helper for
the demo, the benchmarks and the tests, on the simulators' `ChildProcess`.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from orccadd.ctl.client import Client, ClientError
from orccadd.simproc import ChildProcess

UP_TIMEOUT_S = 90.0  # a CANopen bus's startup, on a busy machine
STOP_TIMEOUT_S = 20.0  # a safe stop and the hardware released, before SIGKILL


class DaemonError(Exception):
    """The daemon did not come up, or exited; the message ends with its log."""


class DaemonProcess(ChildProcess):
    """`orccadd --config CONFIG --socket SOCKET EXTRA…`, its output in `log`. `new_session`: in
    a session of its own (as a service or a shell job is: a Ctrl-C at the terminal reaches its
    parent alone). Raises `DaemonError` if it exits or does not answer within `up_timeout_s`."""

    def __init__(
        self,
        config: Path | str,
        socket: Path | str,
        log: Path,
        *extra: str,
        new_session: bool = False,
        up_timeout_s: float = UP_TIMEOUT_S,
    ) -> None:
        self.socket = str(socket)
        self.log = log
        args = ["--config", str(config), "--socket", self.socket, *extra]
        super().__init__(
            "orccadd.daemon.rtproc",
            args,
            what="orccadd",
            ready=None,  # up once it answers
            log_path=log,
            new_session=new_session,
            stop_timeout_s=STOP_TIMEOUT_S,
        )
        try:
            self._wait_up(up_timeout_s)
        except BaseException:
            self.stop()
            raise

    def _wait_up(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while True:
            if self.proc.poll() is not None:
                raise DaemonError(f"orccadd exited (code {self.proc.returncode}):\n{self.log_text(20_000)}")
            try:
                self.call("ping")
                return
            except (ClientError, OSError):
                if time.monotonic() > end:
                    raise DaemonError(
                        f"orccadd did not answer within {timeout_s:g} s:\n{self.log_text(20_000)}"
                    ) from None
                time.sleep(0.05)

    # ---- talking to it --------------------------------------------------------------------
    def client(self, timeout_s: float = 60.0) -> Client:
        """A connection (a load compiles in a process of its own at normal priority: on a busy
        machine, beside a real-time loop and simulators, far longer than a client's 10 s)."""
        return Client(self.socket, timeout_s=timeout_s)

    def call(self, cmd: str, **args: Any) -> Any:
        with self.client() as c:
            return c.call(cmd, **args)

    def reply(self, cmd: str, **args: Any) -> dict[str, Any]:
        with self.client() as c:
            return c.reply(cmd, **args)

    def status(self) -> dict[str, Any]:
        s = self.call("status")
        assert isinstance(s, dict)
        return s

    def wait(self, pred: Callable[[dict[str, Any]], bool], timeout_s: float = 30.0) -> dict[str, Any]:
        """The first status for which `pred` holds; `DaemonError` (with the last status and the
        log) after `timeout_s`."""
        return self.wait_for(pred, timeout_s, interval_s=0.05)

    def timed_out(self, why: str) -> Exception:
        return DaemonError(f"timed out: {why}\nlog:\n{self.log_text(20_000)}")

    def ctl(self, *argv: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
        """`orccadctl ARGV…` as a process of its own, on this daemon's socket."""
        env = {**os.environ, "ORCCADD_SOCKET": self.socket}
        cmd = [sys.executable, "-m", "orccadd.cli", *argv]
        return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout_s)
