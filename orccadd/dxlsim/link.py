"""The serial line: a pseudo-terminal linked where the controller expects the chain's port, and
the wire time of every byte on it.

A pty has no baud rate, so the line's timing is ours: a byte takes 10 bit times (start bit,
8 data bits, stop bit; 8N1 as the X series use) at the configured rate. An instruction has
arrived when its last byte would have, counted from the arrival of its first; each addressed
servo then waits its Return Delay Time(9) (2 µs units) after the bus went quiet and sends its
status packet, which reaches the controller when its last byte would. A controller thus sees
the cycle times of a real chain at that rate (not counting its USB adapter's latency).
"""

from __future__ import annotations

import logging
import os
import tty
from pathlib import Path

log = logging.getLogger("orccadd.dxlsim")

BITS_PER_BYTE = 10


class PtyLink:
    """The servos' end of a pseudo-terminal whose other end is linked at `path`.

    The link replaces a stale symbolic link (a simulator that died) but never a file or device;
    `close` removes it only if it is still ours."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if self.path.exists() and not self.path.is_symlink():
            raise FileExistsError(f"{self.path} exists and is not a symbolic link: not replaced")
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line discipline: bytes pass as they are
        os.set_blocking(self.master, False)
        self.tty_name = os.ttyname(self._slave)
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}")
        try:
            tmp.unlink(missing_ok=True)
            os.symlink(self.tty_name, tmp)
            os.replace(tmp, self.path)
        except OSError:
            os.close(self.master)
            os.close(self._slave)
            raise

    def read(self) -> bytes:
        """Whatever the controller wrote since the last call (b"" if nothing)."""
        try:
            return os.read(self.master, 65536)
        except (BlockingIOError, InterruptedError):
            return b""

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.master, view) :]
            except BlockingIOError:  # the controller is not reading: its buffer is full
                log.warning("serial link full: %d bytes dropped", len(view))
                return

    def close(self) -> None:
        try:
            if self.path.is_symlink() and os.readlink(self.path) == self.tty_name:
                self.path.unlink()
        finally:
            os.close(self.master)
            os.close(self._slave)


def wire_time_s(n_bytes: int, baud: int) -> float:
    """How long `n_bytes` take on the line at `baud` bit/s."""
    return n_bytes * BITS_PER_BYTE / baud
