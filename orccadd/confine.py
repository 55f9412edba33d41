"""Files a client names, opened only inside the directories the config allows.

The daemon runs as a privileged user and a client names a mission (and, through it, task
files). Checking a path and opening it later leaves a window: a link renamed over the file in
between, a FIFO that blocks the reader, a file outside the allowed directories read and quoted
back in an error. So a file is opened once, without following a link at its end and without
blocking, and the *descriptor* is checked: a regular file, whose real path (the kernel's, from
/proc/self/fd) lies inside one of the directories. Whoever reads it reads that descriptor.

Refusals never say whether a file outside the directories exists, nor quote it.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Sequence
from pathlib import Path

from orccadd.errors import OrccaddError

OPEN_FLAGS = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY


class ConfinementError(OrccaddError):
    """A file outside the allowed directories, absent, or not a regular file."""


class Confinement:
    """The directories files may be read from, and what to call them in a refusal.

    `what` names the files ("mission", "task file"); `key` the config key listing `dirs`
    ("daemon.mission_dirs")."""

    def __init__(self, dirs: Sequence[str | Path], what: str, key: str) -> None:
        self.dirs = tuple(Path(os.path.realpath(d)) for d in dirs)
        self.what = what
        self.key = key

    def inside(self, path: str | Path) -> bool:
        p = Path(path)
        return any(p == d or p.is_relative_to(d) for d in self.dirs)

    def open(self, path: str | Path) -> tuple[int, str]:
        """An open descriptor of `path` (O_RDONLY, non-blocking, close-on-exec) and its real path,
        checked as the module says; `ConfinementError` otherwise. The caller closes it."""
        shown = str(path)[:300].encode("utf-8", "backslashreplace").decode()
        try:
            real = os.path.realpath(path)
        except (OSError, ValueError):  # a NUL, a name too long
            raise self._outside(shown) from None
        if not self.inside(real):
            raise self._outside(shown)
        try:
            fd = os.open(real, OPEN_FLAGS)
        except FileNotFoundError:
            raise ConfinementError(f"{shown}: no such {self.what}") from None
        except (OSError, ValueError) as e:  # ELOOP: a link put there since realpath, EACCES, ...
            if isinstance(e, OSError) and e.errno == errno.ELOOP:
                raise self._outside(shown) from None
            raise ConfinementError(f"{shown}: no such {self.what} (cannot open it)") from None
        try:
            opened = os.readlink(f"/proc/self/fd/{fd}")
            if not self.inside(opened):  # a directory on the way swapped for a link meanwhile
                raise self._outside(shown)
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise ConfinementError(f"{shown}: no such {self.what} (not a regular file)")
        except BaseException:
            os.close(fd)
            raise
        return fd, opened

    def read(self, path: str | Path, max_bytes: int) -> tuple[bytes, str]:
        """The content of `path` (at most `max_bytes`, else `ConfinementError`) and its real path."""
        fd, real = self.open(path)
        try:
            data = read_fd(fd, max_bytes)
        finally:
            os.close(fd)
        if data is None:
            raise ConfinementError(f"{str(path)[:300]}: larger than {max_bytes} bytes: not a {self.what}")
        return data, real

    def _outside(self, shown: str) -> ConfinementError:
        allowed = ", ".join(str(d) for d in self.dirs) or "none configured"
        return ConfinementError(f"{shown}: {self.what}s are loaded from {allowed} only ({self.key})")


def read_fd(fd: int, max_bytes: int) -> bytes | None:
    """Everything `fd` holds from its current offset, or None if it holds more than `max_bytes`
    (a regular file: never blocks)."""
    os.set_blocking(fd, True)
    chunks: list[bytes] = []
    size = 0
    while chunk := os.read(fd, min(1 << 20, max_bytes + 1 - size)):
        chunks.append(chunk)
        size += len(chunk)
        if size > max_bytes:
            return None
    return b"".join(chunks)
