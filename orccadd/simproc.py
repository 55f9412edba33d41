"""A simulator (or the virtual CAN hub) as a child process of a test, benchmark or demo.

`ChildProcess` starts `python -m MODULE ARGS`, keeps its log in a file (a pipe nobody reads
would block it once full), waits for its ready line on stdout, and stops it (SIGTERM, then
SIGKILL after `STOP_TIMEOUT_S`). The child gets SIGTERM when its parent dies (Linux
`PR_SET_PDEATHSIG`): a test killed half-way, even by pytest-timeout's `os._exit`, leaves no
simulator running at real-time priority behind it. `SimulatorProcess` adds the device
simulators' control channel (`orccadd.runtime.sim_control`'s protocol: inject, status), whose
client, `control_request`, `python -m orccadd.simctl` uses too. Standard library only.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
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
from typing import Any, Self

PR_SET_PDEATHSIG = 1
STOP_TIMEOUT_S = 10.0


def _prctl() -> Any:
    """libc's prctl, looked up once in the parent: a forked child must not load a library
    (the loader's lock may be held by another thread of the parent at the fork)."""
    global _PRCTL
    if _PRCTL is None:
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            _PRCTL = libc.prctl
    return _PRCTL


_PRCTL: Any = None


def die_with_parent() -> None:
    """In the child, between fork and exec: SIGTERM when the parent dies (only a prctl)."""
    if _PRCTL is not None:
        _PRCTL(PR_SET_PDEATHSIG, signal.SIGTERM)


class ChildProcess:
    """A running child, `python -m MODULE ARGS`. With `ready`, it is up once it has printed a
    line containing `ready` on stdout (that line is `ready_line`; stderr goes to the log); without,
    its stdout and stderr both go to the log and the caller decides when it is up. The log is
    `log_path` if given (kept), else a temporary file."""

    def __init__(
        self,
        module: str,
        args: list[str],
        *,
        what: str,
        ready: str | None,
        env: dict[str, str] | None = None,
        cwd: str | Path | None = None,
        timeout_s: float = 60.0,
        log_path: Path | None = None,
        new_session: bool = False,
        stop_timeout_s: float = STOP_TIMEOUT_S,
    ) -> None:
        self.what = what
        self.stop_timeout_s = stop_timeout_s
        # lives as long as the process
        opened = log_path.open("w+", errors="replace") if log_path else None
        self._log = opened or tempfile.TemporaryFile("w+", errors="replace")  # noqa: SIM115
        _prctl()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE if ready is not None else self._log,
            stderr=self._log if ready is not None else subprocess.STDOUT,
            text=True,
            cwd=cwd,
            env={**os.environ, **(env or {})},
            preexec_fn=die_with_parent,
            start_new_session=new_session,
        )
        self.ready_line = ""
        if ready is None:
            return
        assert self.proc.stdout is not None
        readable, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        self.ready_line = self.proc.stdout.readline() if readable else ""
        if ready not in self.ready_line:
            self.stop()
            raise RuntimeError(f"{what} did not start: {self.ready_line!r} {self.log_text()}")

    def log_text(self, last_chars: int = 0) -> str:
        """What the child logged so far (its last `last_chars` characters, if given)."""
        self._log.flush()
        self._log.seek(0)
        text = self._log.read()
        return text[-last_chars:] if last_chars else text

    def status(self) -> dict[str, Any]:
        """The child's state as it reports it (subclasses that have a way to ask)."""
        raise NotImplementedError(f"{self.what} reports no status")

    def wait_for(
        self, predicate: Callable[[dict[str, Any]], bool], timeout_s: float = 10.0, interval_s: float = 0.02
    ) -> dict[str, Any]:
        """Poll `status()` until `predicate` holds; that status (`timed_out` if it never does)."""
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise self.timed_out(f"condition not met in {timeout_s:g} s; last status {st}")
            time.sleep(interval_s)

    def timed_out(self, why: str) -> Exception:
        return TimeoutError(f"{self.what}: {why}")

    def kill(self) -> None:
        """SIGKILL, at once (a device or bus that dies, for fault tests)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def stop(self, timeout_s: float | None = None) -> int:
        """SIGTERM, SIGKILL after `timeout_s` (default: `stop_timeout_s`); its exit code."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=self.stop_timeout_s if timeout_s is None else timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            with contextlib.suppress(OSError):
                self.proc.stdout.close()
        return int(self.proc.returncode)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


def ready_fields(line: str) -> dict[str, str]:
    """`NAME: ready, port /dev/pts/3, control 127.0.0.1:4711` -> {"port": ..., "control": ...}."""
    _, _, rest = line.partition(": ready")
    pairs = (part.strip().split(" ", 1) for part in rest.split(",") if part.strip())
    return {p[0]: p[1] for p in pairs if len(p) == 2}


def control_address(control: str) -> tuple[str, int] | str:
    """A control channel's address as a simulator's ready line names it: `HOST:PORT` (TCP), or a
    UNIX socket's path (one with a `/`, or an existing socket); `ValueError` for anything else."""
    if "/" in control or Path(control).is_socket():
        return control
    host, sep, port = control.rpartition(":")
    if sep and host and port.isdigit() and 0 < int(port) < 65536:
        return host, int(port)
    raise ValueError(
        f"control address (={control!r}) must be HOST:PORT or a UNIX socket's path, as the "
        "simulator's ready line names it (`control 127.0.0.1:PORT`)"
    )


def control_connect(control: str, timeout_s: float) -> socket.socket:
    """A connection to the simulator's control channel at `control` (`control_address`)."""
    address = control_address(control)
    if isinstance(address, tuple):
        return socket.create_connection(address, timeout=timeout_s)
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(timeout_s)
    try:
        s.connect(address)
    except OSError:
        s.close()
        raise
    return s


def control_request(control: str, req: dict[str, Any], timeout_s: float = 10.0) -> dict[str, Any]:
    """One request of the control protocol (`orccadd.runtime.sim_control`) on `control`, and the
    simulator's reply as it came, a refusal (`{"ok": false, "error": ...}`) included. `OSError`
    if the channel cannot be reached or closes, `ValueError` if the reply is not a JSON object."""
    with control_connect(control, timeout_s) as s, s.makefile("rwb") as f:
        f.write(json.dumps(req).encode() + b"\n")
        f.flush()
        line = f.readline()
    if not line:
        raise ConnectionError(f"{control} closed the connection without a reply")
    reply = json.loads(line)
    if not isinstance(reply, dict):
        raise ValueError(f"{control} replied {line[:200]!r}, not a JSON object")
    return reply


class SimulatorProcess(ChildProcess):
    """A device simulator (`python -m MODULE --config CONFIG ...`) and its control channel: the
    `control` address of its ready line, `127.0.0.1:PORT` or a UNIX socket's path."""

    module = ""
    what = ""

    def __init__(
        self, config: str | Path, *extra: str, env: dict[str, str] | None = None, timeout_s: float = 60.0
    ) -> None:
        args = ["--config", str(config), *extra]
        super().__init__(self.module, args, what=self.what, ready="ready", env=env, timeout_s=timeout_s)
        self.fields = ready_fields(self.ready_line)
        self.control = self.fields["control"]

    def request(self, req: dict[str, Any], timeout_s: float = 10.0) -> dict[str, Any]:
        """One request, its reply; `RuntimeError` with the simulator's words if it refused."""
        reply = control_request(self.control, req, timeout_s)
        if not reply.get("ok"):
            raise RuntimeError(f"{self.what}: {reply.get('error')}")
        return reply

    def inject(self, fault: str, device: int | None = None, **params: Any) -> None:
        """`fault` into the simulator (into one of its devices: a node id, a servo ID), with the
        fault's parameters (the simulator's `--help` and module documentation list them)."""
        self.request({"inject": fault, **({"device": device} if device is not None else {}), **params})

    def status(self) -> dict[str, Any]:
        """`q_rad`, `dq_rad_s`, `devices` ({"id", "state", "fault"} each) and the simulator's own."""
        return self.request({"status": True})
