"""The `ur_rtde` resource's side of a UR controller's links, which live in a process of their own
(`link_server`: ur_rtde can crash the process it runs in after a dropped connection).

- `connect` starts the process and waits until its links are up (the same checks as before:
  model, version, period, power); `close` ends it at once (SIGKILL: nothing in it is worth the
  0.5 s per client ur_rtde's destructors take), tick-safe, and reaps it later;
- the stream: the process sends every package's `StreamState`; `wait_for_package` blocks on the
  socket until one with a new controller timestamp (the tick released by its arrival), `state`
  is the latest;
- stream commands (`send`: servoJ, speedJ, directTorque, kickWatchdog) go one way, in the tick;
  a refusal comes back and is taken by the next tick (`take_refusal`);
- calls (`call`): the dashboard's and the script's slow work (power, unlock, restart, the
  watchdog, measurements), answered, each with a timeout.

The process gone (its socket closed, e.g. a segmentation fault in ur_rtde) is `dead` with the words
of its end; every later call raises `LinkDown`, the stream is silent.
"""

from __future__ import annotations

import contextlib
import logging
import os
import pickle
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Any

from orccadd.drivers.ur.controller import Condition, Version
from orccadd.drivers.ur.rtde_stream import StreamState
from orccadd.drivers.ur.settings import UrRtdeSettings
from orccadd.errors import ResourceError

log = logging.getLogger("orccadd.ur")

MAX_MESSAGE = 1 << 16
START_MARGIN_S = 10.0  # the process's own start (imports) beyond the settings' connect timeout
CALL_TIMEOUT_S = 5.0  # a call on the script or the dashboard answers well within this


class LinkDownError(ResourceError):
    """The link process has ended, or did not answer a call in time."""


class RemoteLink:
    """A UR controller's links in their own process (`link_server`), for one resource."""

    def __init__(self, settings: UrRtdeSettings, period_s: float, name: str) -> None:
        self.settings = settings
        self.period_s = period_s
        self.name = name
        self.version: Version | None = None
        self.robot_model = ""
        # `reset` and `clear_stop` hold it over their slow work; a tick that finds it taken
        # leaves the link alone (as with the links in this process before)
        self.lock = threading.Lock()
        self.watchdog_armed = False
        self.state: StreamState | None = None
        self.dead = ""  # why the process ended ("" while it runs)
        self.process: subprocess.Popen[bytes] | None = None
        self._sock: socket.socket | None = None
        self._io = threading.Lock()  # one reader of the socket at a time
        self._seq = 0
        self._refusal: tuple[str, str] | None = None
        self._gone: list[subprocess.Popen[bytes]] = []  # killed, to be reaped off the tick

    # ---- the process ------------------------------------------------------------------------
    def connect(self) -> None:
        """Start the link process, wait until its links are up (or raise its words)."""
        self.close()
        with self._io:
            self._discard_socket()
        self._reap()
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        cmd = [sys.executable, "-m", "orccadd.drivers.ur.link_server", "--fd", str(theirs.fileno())]
        try:
            self.process = subprocess.Popen(cmd, pass_fds=(theirs.fileno(),), start_new_session=True)
        finally:
            theirs.close()
        self._sock, self.dead, self.state, self._refusal = ours, "", None, None
        ours.send(pickle.dumps((self.settings, self.period_s, self.name)))
        wait_s = self.settings.connect_timeout_s + START_MARGIN_S
        first = self._receive_until(lambda m: m[0] in ("ready", "failed"), wait_s)
        if first is None:
            why = self.dead or f"no answer in {wait_s:g} s"
            self.close()
            raise ResourceError(f"{self.name}: the UR link process: {why}")
        if first[0] == "failed":
            self.close()
            raise ResourceError(first[1])
        _, self.version, self.robot_model, warnings = first
        for w in warnings:
            log.warning("%s: link process: %s", self.name, w)
        self.watchdog_armed = False
        got = self._receive_until(lambda m: m[0] == "state", self.settings.connect_timeout_s)
        if got is None:
            self.close()
            raise ResourceError(f"{self.name}: connected, but no RTDE package came ({self.dead or 'none'})")
        self.state = got[1]

    def close(self) -> None:
        """End the process at once (tick-safe: one signal; its socket then reads as ended, and
        it is reaped at the next connect or at `shutdown`)."""
        p, self.process = self.process, None
        if p is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p.pid, signal.SIGKILL)
            self._gone.append(p)
        self.dead = self.dead or "the UR link process was ended"

    def _discard_socket(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def shutdown(self) -> None:
        """Ask the process to end (its links closed by the kernel as it exits), then reap it."""
        if self._sock is not None and not self.dead:
            with contextlib.suppress(OSError):
                self._sock.send(pickle.dumps(("quit",)))
            p = self.process
            if p is not None:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    p.wait(timeout=1.0)
        self.close()
        with self._io:
            self._discard_socket()
        self._reap()

    def _reap(self) -> None:
        for p in self._gone:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=2.0)
        self._gone = [p for p in self._gone if p.returncode is None]

    def _ended(self) -> None:
        """The socket closed under us: say how the process ended."""
        p = self.process
        code = None
        if p is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                code = p.wait(timeout=0.05)
        if code is not None and code < 0:
            self.dead = f"the UR link process ended by {signal.Signals(-code).name}"
        elif code is not None:
            self.dead = f"the UR link process exited with status {code}"
        elif not self.dead:
            self.dead = "the UR link process closed its socket"
        self._discard_socket()

    # ---- messages ---------------------------------------------------------------------------
    def _take(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == "state":
            self.state = message[1]
        elif kind == "refused" and self._refusal is None:
            self._refusal = (message[1], message[2])

    def _receive_until(self, want: Any, timeout_s: float) -> tuple[Any, ...] | None:
        """Messages taken in until one that `want`s (returned), the timeout (None) or the end."""
        end = time.monotonic() + timeout_s
        sock = self._sock
        while sock is not None:
            left = end - time.monotonic()
            if left <= 0:
                return None
            try:
                ready, _, _ = select.select([sock], [], [], left)
                if not ready:
                    return None
                data = sock.recv(MAX_MESSAGE)
            except (OSError, ValueError):  # closed meanwhile
                data = b""
            if not data:
                self._ended()
                return None
            message = pickle.loads(data)
            if want(message):
                return message  # type: ignore[no-any-return]
            self._take(message)
            sock = self._sock
        return None

    def _drain(self) -> None:
        """Every message already waiting, taken in (non-blocking)."""
        sock = self._sock
        while sock is not None:
            try:
                data = sock.recv(MAX_MESSAGE, socket.MSG_DONTWAIT)
            except BlockingIOError:
                return
            except OSError:
                data = b""
            if not data:
                self._ended()
                return
            self._take(pickle.loads(data))
            sock = self._sock

    # ---- the stream (tick-safe) -------------------------------------------------------------
    def wait_for_package(self, last_stamp: float, timeout_s: float) -> int:
        """Until a package with a controller timestamp other than `last_stamp`, or word that the
        links are down: its arrival (CLOCK_MONOTONIC ns), or -1 after `timeout_s` or with the
        process gone."""
        if not self._io.acquire(timeout=timeout_s):
            return -1
        try:
            self._drain()
            st = self.state
            if st is not None and (st.stamp != last_stamp or not st.connected):
                return st.arrival_ns
            got = self._receive_until(
                lambda m: m[0] == "state" and (m[1].stamp != last_stamp or not m[1].connected), timeout_s
            )
            if got is None:
                return -1
            self.state = got[1]
            return int(got[1].arrival_ns)
        finally:
            self._io.release()

    def read(self) -> StreamState | None:
        """The latest package, every waiting message taken in first (None before the first)."""
        if self._io.acquire(blocking=False):
            try:
                self._drain()
            finally:
                self._io.release()
        return self.state

    def send(self, method: str, *args: Any) -> bool:
        """A stream command, one way; False if the process is gone."""
        sock = self._sock
        if sock is None:
            return False
        try:
            message = pickle.dumps(("send", method, args), protocol=pickle.HIGHEST_PROTOCOL)
            sock.send(message, socket.MSG_DONTWAIT)
        except OSError:
            return False
        return True

    def take_refusal(self) -> tuple[str, str] | None:
        """The first stream command the controller refused since the last call: (method, words;
        words empty when it just returned false, ur_rtde's exception's otherwise)."""
        r, self._refusal = self._refusal, None
        return r

    # ---- calls (not for a tick) -------------------------------------------------------------
    def call(self, target: str, method: str, *args: Any, timeout_s: float = CALL_TIMEOUT_S) -> Any:
        """`target.method(*args)` in the link process (`link`: the `UrLink`; `control`, `io`:
        ur_rtde's control and I/O interfaces); its error raised here as a `ResourceError`."""
        with self._io:
            sock = self._sock
            if sock is None:
                raise LinkDownError(f"{self.name}: {self.dead or 'the UR link process is not running'}")
            self._seq += 1
            seq = self._seq
            try:
                sock.send(pickle.dumps(("call", seq, target, method, args), protocol=pickle.HIGHEST_PROTOCOL))
            except OSError:
                self._ended()
                raise LinkDownError(f"{self.name}: {self.dead}") from None
            reply = self._receive_until(lambda m: m[0] == "reply" and m[1] == seq, timeout_s)
        if reply is None:
            why = self.dead or f"{target}.{method} not answered in {timeout_s:g} s"
            raise LinkDownError(f"{self.name}: {why}")
        _, _, ok, value = reply
        if not ok:
            raise ResourceError(str(value))
        return value

    def power_on(self) -> None:
        self.call("link", "power_on", timeout_s=2 * self.settings.connect_timeout_s)

    def power_off(self) -> None:
        self.call("link", "power_off")

    def unlock_protective_stop(self) -> None:
        self.call("link", "unlock_protective_stop")

    def restart_script(self) -> None:
        """The script stopped with the controller's stop: start it again, its watchdog too."""
        self.call("link", "restart_script", timeout_s=self.settings.connect_timeout_s)
        self.watchdog_armed = False

    def arm_watchdog(self, watchdog_s: float) -> None:
        """The controller's RTDE watchdog, armed by the first command of a (re)started script
        (`UrLink.arm_watchdog`): a round trip to the script, once."""
        if not self.watchdog_armed:
            self.call("control", "setWatchdog", 1.0 / watchdog_s)
            self.watchdog_armed = True

    def condition(self) -> Condition | None:
        st = self.read()
        return None if st is None else st.condition()

    def measured(self) -> dict[str, float | int | str]:
        """What the controller measures beyond the joint state (`UrLink.measured`)."""
        if self.dead:
            return {}
        try:
            return dict(self.call("link", "measured", timeout_s=0.5))
        except ResourceError:
            return {}
