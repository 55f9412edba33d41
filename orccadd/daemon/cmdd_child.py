"""The command daemon as the real-time process's child: started, watched through its pidfd, and
started again when it exits (ever more slowly while it dies at once), ended at shutdown.

It runs in a process group of its own: a group-wide SIGTERM/SIGINT reaches the real-time process
alone, which safe-stops the arm first and then ends its children (systemd: KillMode=mixed).
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import time

log = logging.getLogger("orccadd")

RESPAWN_DELAY_S = 1.0
RESPAWN_MAX_S = 60.0
RESPAWN_STABLE_S = 10.0  # a command daemon that lived this long had started fine
TERMINATE_WAIT_S = 3.0  # how long shutdown waits after SIGTERM before SIGKILL


class CommandDaemonChild:
    """`orccadd.cmdd` on the station config `config`, serving `socket_path`, attached to the
    link at `rt_path` and the daemon's telemetry block `block`."""

    def __init__(self, config: str, socket_path: str, rt_path: str, block: str) -> None:
        self.cmd = [
            sys.executable, "-m", "orccadd.cmdd", "--config", config,
            "--socket", socket_path, "--rt-socket", rt_path, "--telemetry", block,
        ]  # fmt: skip
        self.proc: subprocess.Popen[bytes] | None = None
        self.pidfd = -1  # readable once it has exited (-1: none, or no pidfd on this kernel)
        self.started_s = 0.0
        self.respawn_at = 0.0  # when to start it again (0: not waiting to)
        self.respawn_delay_s = RESPAWN_DELAY_S / 2  # doubled before the first respawn

    def spawn(self) -> None:
        self.proc = subprocess.Popen(self.cmd, stdin=subprocess.DEVNULL, start_new_session=True)
        self.started_s = time.monotonic()
        try:
            self.pidfd = os.pidfd_open(self.proc.pid)
        except OSError:
            self.pidfd = -1

    def exited(self) -> int | None:
        """Its pidfd was readable: its exit code once it has exited (None: not yet), and its
        next start scheduled."""
        if self.proc is not None:
            code = self.proc.poll()
            if code is None:
                return None
            self.proc = None
        else:
            code = None
        if self.pidfd >= 0:
            os.close(self.pidfd)
            self.pidfd = -1
        # one that dies at once (its socket unusable) is retried ever more slowly, not in a loop
        short_lived = time.monotonic() - self.started_s < RESPAWN_STABLE_S
        self.respawn_delay_s = (
            min(RESPAWN_MAX_S, 2 * self.respawn_delay_s) if short_lived else RESPAWN_DELAY_S
        )
        log.warning("command daemon exited (code %s): restarting it in %g s", code, self.respawn_delay_s)
        self.respawn_at = time.monotonic() + self.respawn_delay_s
        return code if code is not None else -1

    def respawn_due(self) -> None:
        """Start it again if it exited and its delay has passed."""
        if self.proc is None and self.respawn_at and time.monotonic() >= self.respawn_at:
            self.respawn_at = 0.0
            self.spawn()

    def end(self, wait_s: float | None = TERMINATE_WAIT_S) -> None:
        """SIGTERM, then SIGKILL after `wait_s` (None: wait as long as it takes)."""
        if self.proc is None:
            return
        self.proc.terminate()
        try:
            self.proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.proc = None
