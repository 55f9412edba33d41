"""The terminal side of `orccadctl top`: keys read one at a time (cbreak: no Enter needed,
Ctrl-C still interrupts) and frames drawn in place with ANSI sequences. Off a terminal: no
keys, and each frame printed after the previous one, without colour."""

from __future__ import annotations

import os
import select
import shutil
import sys
import termios
import time
import tty
from typing import Any, TextIO

FALLBACK_SIZE = (100, 40)  # frames written to a file or a pipe


def colour_wanted(out: TextIO) -> bool:
    """Colours only on a terminal, and not when $NO_COLOR is set (no-color.org: to a non-empty value)."""
    return out.isatty() and not os.environ.get("NO_COLOR")


class TerminalKeys:
    """Keys of a terminal on `fd` (cbreak while inside `with`); none if `fd` is not a terminal."""

    def __init__(self, fd: int | None = None) -> None:
        try:
            self.fd = sys.stdin.fileno() if fd is None else fd
            self.tty = os.isatty(self.fd)
        except (OSError, ValueError):  # no stdin, or one without a file descriptor
            self.fd, self.tty = -1, False
        self._saved: list[Any] | None = None

    def __enter__(self) -> TerminalKeys:
        if self.tty:
            self._saved = termios.tcgetattr(self.fd)
            tty.setcbreak(self.fd)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._saved is not None:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            self._saved = None

    def read(self, timeout_s: float) -> str | None:
        if not self.tty:
            time.sleep(timeout_s)
            return None
        ready, _, _ = select.select([self.fd], [], [], timeout_s)
        if not ready:
            return None
        data = os.read(self.fd, 32)  # one key, or one escape sequence (an arrow key): ignored
        if not data or data.startswith(b"\x1b"):
            return ""
        return data[:1].decode("ascii", errors="replace")


class AnsiScreen:
    """Frames drawn over each other on a terminal (alternate screen, cursor hidden while
    inside `with`), or printed one after the other elsewhere."""

    def __init__(self, out: TextIO | None = None) -> None:
        self.out = out or sys.stdout
        self.tty = self.out.isatty()
        self.colour = colour_wanted(self.out)

    def __enter__(self) -> AnsiScreen:
        if self.tty:
            self.out.write("\x1b[?1049h\x1b[?25l")
        return self

    def __exit__(self, *exc: object) -> None:
        if self.tty:
            self.out.write("\x1b[?25h\x1b[?1049l")
            self.out.flush()

    def size(self) -> tuple[int, int]:
        if self.tty:
            try:
                cols, lines = os.get_terminal_size(self.out.fileno())
                return cols, lines
            except OSError:
                pass
        cols, lines = shutil.get_terminal_size(FALLBACK_SIZE)
        return cols, lines

    def draw(self, lines: list[str]) -> None:
        if self.tty:
            self.out.write("\x1b[H" + "\x1b[K\n".join(lines) + "\x1b[K\x1b[J")
        else:
            self.out.write("\n".join(lines) + "\n\n")
        self.out.flush()
