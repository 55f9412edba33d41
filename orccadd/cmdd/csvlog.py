"""Full-rate CSV logs of chosen signals, in the daemon's log directory, that outlive a command
daemon: the log in progress is described in a state file next to it, so that the command daemon
the real-time process starts after one died carries the log on from its last complete row, with
the ticks of the gap taken from the telemetry ring (16 s of ticks; beyond, counted as lost).
A write error (a full disk) ends the log with the reason in `status`; nothing else is touched.

The file: `HEADER_LINES` comment lines (the log's wall-clock start and time origin as JSON, the
units as JSON, a line saying how to read it), the column names (`time_s` first, seconds since the
start of the log), then the rows, with the log's events as comment lines among them
(`# event,<time_s>,<trace seq>,<kind>,<name>,<detail>`). `pandas.read_csv(f, comment="#")` and
`numpy.loadtxt(f, delimiter=",", skiprows=4)` read it as it is. A unit given by mode (`cmd`: the
command sent is a position, a velocity or a torque) is written `{"<mode>": "<unit>", ...}`, the
mode in force told by the `mode` events.

Every file is opened relative to the directory's descriptor with O_NOFOLLOW (new logs O_EXCL):
nothing a client names can make the root daemon write through a link or outside the directory.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from orccadd.cmdd.logfeed import MODE_UNITS, FloatArray, LogEvent, LogOrigin, base_signal, unit
from orccadd.cmdd.views import SignalSelection
from orccadd.wire.schema import T
from orccadd.wire.socketdir import SocketPathError, prepare_socket_dir

LOG_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}\.csv")
PART_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,110}\.mcap")  # derived from a log's name
STATE_FILE = ".active-log.json"  # starts with '.': no client can name a log so
TAIL_BYTES = 1 << 16  # enough to find the last complete row
HEADER_LINES = 3  # comment lines before the column names
EVENT_SEQ = re.compile(rb"^# event,[^,\n]*,(\d+),", re.MULTILINE)


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

    def create_fd(self, name: str) -> int:
        """A new file `name` (a log, or a part derived from its name); `ValueError` saying why not."""
        if not (LOG_NAME.fullmatch(name) or PART_NAME.fullmatch(name)):
            raise ValueError(
                f"log: name {name[:120]!r} must be letters, digits, '.', '_' or '-', end in .csv, "
                "and not start with '.' (a file name, not a path)"
            )
        try:
            return self._open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
        except SocketPathError as e:
            raise ValueError(f"log: {e}") from None
        except FileExistsError:
            raise ValueError(f"log: {name} already exists in {self.path}: choose another name") from None
        except OSError as e:
            raise ValueError(f"log: cannot create {name} in {self.path}: {e.strerror}") from None

    def create(self, name: str) -> IO[str]:
        """A new CSV log `name`; `ValueError` saying why not."""
        if not LOG_NAME.fullmatch(name):
            raise ValueError(
                f"log: name {name[:120]!r} must be letters, digits, '.', '_' or '-', end in .csv, "
                "and not start with '.' (a file name, not a path)"
            )
        return os.fdopen(self.create_fd(name), "w", newline="", encoding="utf-8")

    def open_existing(self, name: str) -> int:
        """A part of the log in progress, read-write (never through a link)."""
        if not (LOG_NAME.fullmatch(name) or PART_NAME.fullmatch(name)):
            raise ValueError(f"not a log name: {name!r}")
        return self._open(name, os.O_RDWR)

    def remove(self, name: str) -> None:
        if LOG_NAME.fullmatch(name) or PART_NAME.fullmatch(name):
            with contextlib.suppress(OSError):
                os.unlink(self.path / name)

    def save_state(self, state: dict[str, Any]) -> None:
        """Replace the state file at once (written beside it, then renamed); on a failure (a full
        disk) the old one stays and nothing is left beside it."""
        tmp = f"{STATE_FILE}.{os.getpid()}"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path / tmp)
        try:
            with os.fdopen(self._open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), "w") as fh:
                json.dump(state, fh)
            os.replace(self.path / tmp, self.path / STATE_FILE)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(self.path / tmp)
            raise

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

    def reopen(self, name: str) -> tuple[IO[str], CsvTail]:
        """An existing CSV log, cut after its last complete line, for appending; where it ends."""
        if not LOG_NAME.fullmatch(name):
            raise ValueError(f"not a log name: {name!r}")
        fd = self._open(name, os.O_RDWR)
        size = os.lseek(fd, 0, os.SEEK_END)
        start = max(0, size - TAIL_BYTES)
        tail = os.pread(fd, size - start, start)
        end = tail.rfind(b"\n") + 1
        os.ftruncate(fd, start + end)
        last_t = float("-inf")
        for line in reversed(tail[:end].splitlines()):
            if not line.startswith(b"#"):  # the last row, or the column names if there is none
                with contextlib.suppress(ValueError):
                    last_t = float(line.split(b",", 1)[0])
                break
        lines, comments, last_seq = _scan(fd)
        os.lseek(fd, 0, os.SEEK_END)
        tail_info = CsvTail(last_t, max(lines - comments - 1, 0), last_seq)
        return os.fdopen(fd, "w", newline="", encoding="utf-8"), tail_info


@dataclass(frozen=True)
class CsvTail:
    """Where a CSV log left off: its last row's time (−inf: none), its rows, its last event's
    trace number (−1: none)."""

    last_time_s: float
    rows: int
    last_event_seq: int


def _scan(fd: int) -> tuple[int, int, int]:
    """Lines, comment lines and the highest event number of a file cut after a complete line."""
    os.lseek(fd, 0, os.SEEK_SET)
    carry = b""
    lines = comments = 0
    last_seq = -1
    while chunk := os.read(fd, 1 << 20):
        buf = carry + chunk
        cut = buf.rfind(b"\n") + 1
        whole, carry = buf[:cut], buf[cut:]
        lines += whole.count(b"\n")
        comments += whole.count(b"\n#") + whole.startswith(b"#")
        for m in EVENT_SEQ.finditer(whole):
            last_seq = max(last_seq, int(m.group(1)))
    return lines, comments, last_seq


def header_lines(
    origin: LogOrigin, labels: list[str], meta: dict[str, Any], own: dict[str, str] | None = None
) -> list[str]:
    """The comment lines of a new log (without their line ends); `own`: the units of the
    resource's own signals (a wrench's `N|N.m`)."""
    info = {"start_utc": origin.start_utc, "origin_t_s": origin.t_s, "origin_tick": origin.tick, **meta}
    own = own or {}
    units: dict[str, Any] = {"time_s": "s"} | {
        label.partition(".")[0]: own.get(base_signal(label)) or unit(label) for label in labels
    }
    for group in units:
        if base_signal(group) == "cmd":  # the command's unit is its mode's: see the mode events
            units[group] = {mode.name.lower(): u for mode, u in MODE_UNITS.items()}
    return [
        f"# orccadd log {json.dumps(info)}",
        f"# units {json.dumps(units)}",
        "# time_s: seconds since the log started (the loop's clock minus origin_t_s); events: lines "
        '"# event,<time_s>,<trace seq>,<kind>,<name>,<detail>" among the rows; read with '
        f'pandas.read_csv(f, comment="#") or numpy.loadtxt(f, delimiter=",", skiprows={HEADER_LINES + 1})',
    ]


class CsvLog:
    """Chosen signals at full rate into a CSV file, with the log's events as comment lines
    (PlotJuggler: File > Load Data, time column `time_s`, skipping the header's comment lines).

    Each `write` goes to the file in one piece or not at all: should the disk fill mid-way, the
    file is cut back to its last complete line (a cut row would be a row of wrong numbers)."""

    def __init__(
        self,
        fh: IO[str],
        path: Path,
        selection: SignalSelection,
        origin: LogOrigin,
        meta: dict[str, Any] | None = None,
        rows: int = 0,
    ) -> None:
        """A new log (writes its header), or with `meta` None one carried on after `rows` rows."""
        self.path = path
        self.sel = selection
        self.origin = origin
        self.fh = fh  # owns the descriptor; written through `fd` only (no buffer to flush later)
        self.fd = fh.fileno()
        self.size = os.lseek(self.fd, 0, os.SEEK_END)  # bytes of complete lines
        self.rows = rows
        if meta is not None:
            buf = io.StringIO()
            for line in header_lines(origin, selection.labels, meta, selection.units):
                buf.write(line + "\n")
            csv.writer(buf, lineterminator="\n").writerow(["time_s", *selection.labels])
            self._emit(buf.getvalue())

    def write(self, recs: FloatArray, events: list[LogEvent]) -> None:
        """The new rows, each event just before the first row at or after its time (`OSError`
        if the file cannot take them: then none of them is in it)."""
        cols = self.sel.cols
        t0 = self.origin.t_s
        times = recs[:, T.T_S] - t0
        at: list[int] = np.searchsorted(times, [e.time_s for e in events], side="left").tolist()
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        k = 0
        for i, rec in enumerate(recs):
            while k < len(events) and at[k] <= i:
                self._event(writer, events[k])
                k += 1
            writer.writerow([f"{times[i]:.6f}", *(f"{rec[c]:.9g}" for c in cols)])
        for e in events[k:]:
            self._event(writer, e)
        self._emit(buf.getvalue())
        self.rows += len(recs)

    def _emit(self, text: str) -> None:
        data = memoryview(text.encode("utf-8"))
        written = 0
        try:
            while written < len(data):
                written += os.pwrite(self.fd, data[written:], self.size + written)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self.fd, self.size)  # frees space: always possible on a full disk
            raise
        self.size += written

    @staticmethod
    def _event(writer: Any, e: LogEvent) -> None:
        writer.writerow(["# event", f"{e.time_s:.6f}", e.seq if e.seq >= 0 else "", e.kind, e.name, e.detail])

    def close(self) -> None:
        self.fh.close()
