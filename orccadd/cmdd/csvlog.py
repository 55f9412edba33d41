"""Full-rate CSV logs of chosen signals, in the daemon's log directory, that outlive a command
daemon: the log in progress is described in a state file next to it, so that the command daemon
the real-time process starts after one died carries the log on from its last complete row, with
the ticks of the gap taken from the telemetry ring (16 s of ticks; beyond, counted as lost).
A write error (a full disk) ends the log with the reason in `status`; nothing else is touched.

Every file is opened relative to the directory's descriptor with O_NOFOLLOW (new logs O_EXCL):
nothing a client names can make the root daemon write through a link or outside the directory.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
from pathlib import Path
from typing import IO, Any

import numpy as np

from orccadd.cmdd.views import SignalSelection
from orccadd.wire.schema import H, T
from orccadd.wire.socketdir import SocketPathError, prepare_socket_dir
from orccadd.wire.telemetry import RingReader, TelemetryBlock

LOG_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}\.csv")
STATE_FILE = ".active-log.json"  # starts with '.': no client can name a log so
TAIL_BYTES = 1 << 16  # enough to find the last complete row


class LogDir:
    """The daemon's log directory (created like the socket directory: checked, never chmod'ed)."""

    def __init__(self, path: Path, group: str) -> None:
        self.path = path
        self.group = group

    def _open(self, name: str, flags: int, mode: int = 0o640) -> int:
        gid = prepare_socket_dir(self.path, self.group)
        dir_fd = os.open(self.path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
        try:
            fd = os.open(name, flags | os.O_NOFOLLOW | os.O_CLOEXEC, mode, dir_fd=dir_fd)
        finally:
            os.close(dir_fd)
        if gid >= 0 and flags & os.O_CREAT:
            os.fchown(fd, -1, gid)
        return fd

    def create(self, name: str) -> IO[str]:
        """A new log `name`; `ValueError` saying why not."""
        if not LOG_NAME.fullmatch(name):
            raise ValueError(
                f"log: name {name[:120]!r} must be letters, digits, '.', '_' or '-', end in .csv, "
                "and not start with '.' (a file name, not a path)"
            )
        try:
            fd = self._open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
        except SocketPathError as e:
            raise ValueError(f"log: {e}") from None
        except FileExistsError:
            raise ValueError(f"log: {name} already exists in {self.path}: choose another name") from None
        except OSError as e:
            raise ValueError(f"log: cannot create {name} in {self.path}: {e.strerror}") from None
        return os.fdopen(fd, "w", newline="")

    def save_state(self, state: dict[str, Any]) -> None:
        tmp = f"{STATE_FILE}.{os.getpid()}"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path / tmp)
        with os.fdopen(self._open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), "w") as fh:
            json.dump(state, fh)
        os.replace(self.path / tmp, self.path / STATE_FILE)

    def load_state(self) -> dict[str, Any] | None:
        try:
            with os.fdopen(self._open(STATE_FILE, os.O_RDONLY), "r") as fh:
                state = json.load(fh)
        except (OSError, ValueError, SocketPathError):
            return None
        return state if isinstance(state, dict) else None

    def clear_state(self) -> None:
        with contextlib.suppress(OSError):
            os.unlink(self.path / STATE_FILE)

    def reopen(self, name: str) -> tuple[IO[str], float, int]:
        """An existing log, cut after its last complete row, for appending; that row's time and
        the number of rows."""
        if not LOG_NAME.fullmatch(name):
            raise ValueError(f"not a log name: {name!r}")
        fd = self._open(name, os.O_RDWR)
        size = os.lseek(fd, 0, os.SEEK_END)
        start = max(0, size - TAIL_BYTES)
        tail = os.pread(fd, size - start, start)
        end = tail.rfind(b"\n") + 1
        lines = tail[:end].splitlines()
        last_t = float("-inf")
        if lines and start + end > 0:
            with contextlib.suppress(ValueError):
                last_t = float(lines[-1].split(b",", 1)[0])
        os.ftruncate(fd, start + end)
        rows = -1  # the header
        os.lseek(fd, 0, os.SEEK_SET)
        while chunk := os.read(fd, 1 << 20):
            rows += chunk.count(b"\n")
        return os.fdopen(fd, "w", newline=""), last_t, max(rows, 0)


class CsvLog:
    """Chosen signals at full rate into a CSV file (PlotJuggler: File > Load Data, time column `time_s`)."""

    def __init__(
        self,
        tel: TelemetryBlock,
        fh: IO[str],
        path: Path,
        selection: SignalSelection,
        resume: tuple[int, float, int] | None = None,
    ) -> None:
        """A new log from the next tick, or with `resume` = (the tick the log started after, the
        time of its last complete row, its rows) one carried on from the row after that one."""
        self.path = path
        self.sel = selection
        self.fh = fh
        self.writer = csv.writer(self.fh)
        self.reader = RingReader(tel.ticks, tel.header, H.TICK_HEAD, from_now=True)
        self.start_tick = self.reader.next
        self.resumed = resume is not None
        self.gap_lost = False
        if resume is None:
            self.rows = 0
            self.writer.writerow(["time_s", *selection.labels])
        else:
            self.start_tick, last_t_s, self.rows = resume
            self.reader.next = self._after(tel, last_t_s)

    def _after(self, tel: TelemetryBlock, last_t_s: float) -> int:
        """Where to read on from: the record of the last row written, if the ring still has it."""
        if last_t_s == float("-inf"):
            after = self.start_tick
        else:
            ring = tel.ticks
            hit = np.flatnonzero(np.abs(ring[:, T.T_S] - last_t_s) < 5e-7)
            after = int(ring[hit[0], T.SEQ]) if len(hit) else -1
        oldest = max(0, int(tel.header[H.TICK_HEAD]) - len(tel.ticks))
        if after < oldest:  # the gap is longer than the ring keeps
            self.gap_lost = True
            return oldest
        return after

    def pump(self) -> None:
        """Write the new ticks (`OSError` if the file cannot take them)."""
        recs = self.reader.poll()
        cols = self.sel.cols
        for rec in recs:
            self.writer.writerow([f"{rec[T.T_S]:.6f}", *(f"{rec[c]:.9g}" for c in cols)])
        self.rows += len(recs)
        self.fh.flush()

    def close(self) -> dict[str, Any]:
        self.pump()
        self.fh.close()
        return self.describe()

    def abandon(self, error: OSError) -> dict[str, Any]:
        """The file failed: close what can be closed and say why the log ended."""
        with contextlib.suppress(OSError):
            self.fh.close()
        return {**self.describe(), "error": f"log ended: {error.strerror or error} after {self.rows} rows"}

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "file": str(self.path),
            "rows": self.rows,
            "lost": self.reader.lost,
            "signals": self.sel.labels,
            "resumed": self.resumed,
        }
        if self.gap_lost:
            out["gap"] = "ticks lost while no command daemon ran (longer than the telemetry ring keeps)"
        return out
