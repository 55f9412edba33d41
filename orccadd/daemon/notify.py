"""sd_notify(3) without libsystemd: one datagram to $NOTIFY_SOCKET (a path or an abstract name)."""

from __future__ import annotations

import logging
import os
import socket

log = logging.getLogger("orccadd")


class Notifier:
    """Sends READY=1, WATCHDOG=1, STATUS=..., STOPPING=1 to systemd when run as Type=notify."""

    def __init__(self, address: str | None = None) -> None:
        addr = address if address is not None else os.environ.get("NOTIFY_SOCKET", "")
        self.address = "\0" + addr[1:] if addr.startswith("@") else addr
        self.sock: socket.socket | None = None
        self.failed = False  # a send failed (logged once: the watchdog pings several times a second)
        if self.address:
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
        usec = os.environ.get("WATCHDOG_USEC", "")
        pid = os.environ.get("WATCHDOG_PID", "")
        ok_pid = not pid or pid == str(os.getpid())
        self.watchdog_s = int(usec) * 1e-6 if usec.isdigit() and ok_pid else 0.0

    @property
    def enabled(self) -> bool:
        return self.sock is not None

    def send(self, *fields: str) -> bool:
        if self.sock is None:
            return False
        try:
            self.sock.sendto("\n".join(fields).encode(), self.address)
            return True
        except OSError as e:
            if not self.failed:
                self.failed = True
                log.warning(
                    "sd_notify to %s failed: %s (later failures not logged)",
                    self.address.replace("\0", "@"),
                    e,
                )
            return False

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None
