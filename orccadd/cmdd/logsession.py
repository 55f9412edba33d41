"""One log, from `log start` to `log stop`: the CSV and its MCAP part(s) beside it, fed from the
same records (`LogFeed`), described in the state file so that the command daemon started after
one died carries it on (`resume`): the CSV from its last complete row, the MCAP in a new part
(the unfinished one sealed), the same time origin, the gap filled from the telemetry ring.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from orccadd.cmdd.csvlog import CsvLog, LogDir
from orccadd.cmdd.logfeed import Decoder, LogFeed, LogOrigin
from orccadd.cmdd.mcaplog import McapLog, Urdf, seal
from orccadd.cmdd.views import SignalSelection
from orccadd.wire.schema import H, T
from orccadd.wire.telemetry import TelemetryBlock

log = logging.getLogger("orccadd.cmdd")
MAX_PARTS = 100


def part_name(csv_name: str, part: int) -> str:
    """`run.csv` → `run.mcap` (part 1), `run-2.mcap`, ..."""
    stem = csv_name.removesuffix(".csv")
    return f"{stem}.mcap" if part == 1 else f"{stem}-{part}.mcap"


def tick_at(tel: TelemetryBlock, t_s: float) -> int:
    """The sequence number of the tick at loop time `t_s`: the ring's, or, when the ring no longer
    holds it, counted back from the oldest tick it holds, a period each (what the log misses in
    between is then counted as lost)."""
    ring = tel.ticks
    d = np.abs(ring[:, T.T_S] - t_s)
    d[ring[:, T.SEQ] <= 0] = np.inf
    i = int(np.argmin(d))
    if d[i] < 0.5 * tel.period_s:
        return int(ring[i, T.SEQ])
    valid = ring[:, T.SEQ] > 0
    oldest = int(np.argmin(np.where(valid, ring[:, T.SEQ], np.inf)))
    periods = round((float(ring[oldest, T.T_S]) - t_s) / tel.period_s)
    return max(0, int(ring[oldest, T.SEQ]) - max(1, periods))


class TelemetryLog:
    """Chosen signals at full rate into `<name>.csv` and `<name>.mcap`, events in both."""

    def __init__(
        self,
        logs: LogDir,
        feed: LogFeed,
        csv: CsvLog,
        state: dict[str, Any],
        urdf: Urdf,
        resumed: bool,
    ) -> None:
        self.logs = logs
        self.feed = feed
        self.csv = csv
        self.state = state
        self.urdf = urdf
        self.resumed = resumed
        self.mcap: McapLog | None = None
        self.notes: list[str] = []

    @property
    def path(self) -> Path:
        return self.csv.path

    @staticmethod
    def start(
        logs: LogDir,
        tel: TelemetryBlock,
        name: str,
        sel: SignalSelection,
        desc: Callable[[], dict[str, Any]],
        decode: Decoder,
        urdf_path: Path | None,
        extra_state: dict[str, Any],
    ) -> TelemetryLog:
        """A new log from the next tick; `ValueError` if its files cannot be created."""
        origin = LogOrigin.now(tel)
        if origin.tick == 0:
            raise ValueError("log: the control loop has not ticked yet: no time to start the log from")
        trace_start = int(tel.header[H.TRACE_HEAD])
        meta = {"robot": desc().get("robot"), "period_s": tel.period_s}
        fh = logs.create(name)
        try:
            mcap_fd = logs.create_fd(part_name(name, 1))
        except ValueError:
            fh.close()
            logs.remove(name)
            raise
        csv = CsvLog(fh, logs.path / name, sel, origin, meta)
        feed = LogFeed(tel, origin, decode, origin.tick)
        state = {
            **extra_state,
            "file": name,
            "signals": sel.labels,
            "origin": origin.to_state(),
            "trace_start": trace_start,
            "mcap": [part_name(name, 1)],
        }
        rec = TelemetryLog(logs, feed, csv, state, Urdf.read(urdf_path), resumed=False)
        try:
            rec._open_mcap(os.fdopen(mcap_fd, "wb"), 1, sel, desc, tel.period_s, 0.0)
        except OSError as e:
            csv.close()
            logs.remove(name)
            logs.remove(part_name(name, 1))
            raise ValueError(f"log: cannot write {part_name(name, 1)}: {e.strerror or e}") from None
        return rec

    @staticmethod
    def resume(
        logs: LogDir,
        tel: TelemetryBlock,
        state: dict[str, Any],
        desc: Callable[[], dict[str, Any]],
        decode: Decoder,
        urdf_path: Path | None,
    ) -> TelemetryLog:
        """The log of `state` carried on after its last complete row (`KeyError`, `ValueError`,
        `OSError`... if it cannot be)."""
        name = str(state["file"])
        sel = SignalSelection([str(s) for s in state["signals"]], desc()["joints"])
        origin = LogOrigin.from_state(state["origin"])
        fh, tail = logs.reopen(name)
        last = tail.last_time_s
        after_tick = origin.tick if last == float("-inf") else tick_at(tel, origin.t_s + last)
        after_trace = max(tail.last_event_seq, int(state["trace_start"]))
        feed = LogFeed(tel, origin, decode, after_tick, after_trace)
        csv = CsvLog(fh, logs.path / name, sel, origin, rows=tail.rows)
        rec = TelemetryLog(logs, feed, csv, dict(state), Urdf.read(urdf_path), resumed=True)
        rec._next_part(sel, desc, tel.period_s, max(last, 0.0))
        return rec

    def _next_part(
        self, sel: SignalSelection, desc: Callable[[], dict[str, Any]], period_s: float, from_s: float
    ) -> None:
        """Seal the part a dead command daemon left, carry the MCAP on in a new one."""
        self._seal_last_part("was left unfinished by a command daemon that died: sealed")
        parts: list[str] = [str(p) for p in self.state.get("mcap", [])]
        for n in range(len(parts) + 1, MAX_PARTS + 1):
            name = part_name(str(self.state["file"]), n)
            try:
                fd = self.logs.create_fd(name)
            except ValueError:
                continue
            self.state["mcap"] = [*parts, name]
            try:
                self._open_mcap(os.fdopen(fd, "wb"), n, sel, desc, period_s, from_s)
            except OSError as e:
                self.logs.remove(name)  # an empty or cut part is not an MCAP file
                self.state["mcap"] = parts
                self.notes.append(
                    f"{name} could not be written ({e.strerror or e}): the log goes on in CSV only"
                )
                return
            self.notes.append(f"MCAP carried on in {name} (an MCAP file cannot be appended to)")
            return
        self.notes.append("no new MCAP part could be created: the log goes on in CSV only")

    def _open_mcap(
        self,
        fh: Any,
        part: int,
        sel: SignalSelection,
        desc: Callable[[], dict[str, Any]],
        period_s: float,
        from_s: float,
    ) -> None:
        origin = self.feed.origin
        parts = self.state["mcap"]
        info = {
            "csv": self.state["file"],
            "part": part,
            "continues": parts[-2] if part > 1 and len(parts) > 1 else "",
            "start_utc": origin.start_utc,
            "origin_t_s": repr(origin.t_s),
            "origin_tick": origin.tick,
            "robot": desc().get("robot"),
            "period_s": period_s,
            "signals": ",".join(sel.labels),
            "urdf": str(self.urdf.path) if self.urdf.text else f"none: {self.urdf.missing}",
        }
        path = self.logs.path / parts[-1]
        try:
            self.mcap = McapLog(
                fh, path, sel, desc()["joints"], origin, info, self.urdf, desc, period_s, from_s
            )
        except Exception:
            with contextlib.suppress(OSError):
                fh.close()
            raise

    # ---- running ----------------------------------------------------------------------------
    def pump(self) -> None:
        """Write the new ticks and events: the MCAP first, so that a command daemon dying in
        between leaves the parts overlapping rather than a hole (`OSError` naming the file if
        one cannot take them)."""
        recs, events = self.feed.poll()
        for path, write in ((self._mcap_path(), self._mcap_write), (self.csv.path, self.csv.write)):
            try:
                write(recs, events)
            except OSError as e:
                raise OSError(e.errno, f"{e.strerror or e} ({path})") from e
            except Exception as e:  # a bug in a writer must not stop the command daemon's pump
                raise OSError(f"{type(e).__name__}: {e} ({path})") from e

    def size_bytes(self) -> int:
        """What the log's files hold so far (the CSV and the MCAP part being written)."""
        mcap = self.mcap.fh.tell() if self.mcap is not None else 0
        return self.csv.size + int(mcap)

    def _mcap_path(self) -> Path | None:
        return self.mcap.path if self.mcap else None

    def _mcap_write(self, recs: Any, events: Any) -> None:
        if self.mcap is not None:
            self.mcap.write(recs, events)

    def close(self, reason: str = "log stop") -> dict[str, Any]:
        self.pump()
        summary = self.describe()
        if self.mcap is not None:
            self.mcap.close({"rows": self.csv.rows, "lost": self.feed.lost, "ended": reason})
        self.csv.close()
        return summary

    def abandon(self, error: OSError) -> dict[str, Any]:
        """A file failed (a full disk): close what can be closed, leave every file readable (the
        CSV ends with its last complete row: `CsvLog`; the MCAP part sealed, or removed if it holds
        nothing) and say why the log ended."""
        with contextlib.suppress(OSError, ValueError):
            self.csv.close()
        if self.mcap is not None:
            self.mcap.abandon()
            self.mcap = None
            self._seal_last_part("sealed after the write error (readable to its last record)")
        reason = error.strerror or str(error)
        return {**self.describe(), "error": f"log ended: {reason} after {self.csv.rows} rows"}

    def _seal_last_part(self, why: str) -> None:
        """Leave the last MCAP part readable: sealed to its last record (noted with `why`), or
        removed if it holds nothing (not even its magic)."""
        parts: list[str] = [str(p) for p in self.state.get("mcap", [])]
        if not parts:
            return
        try:
            fd = self.logs.open_existing(parts[-1])
            try:
                if os.fstat(fd).st_size < 8:
                    self.logs.remove(parts[-1])
                    self.state["mcap"] = parts[:-1]
                elif seal(fd):
                    self.notes.append(f"{parts[-1]} {why}")
            finally:
                os.close(fd)
        except (OSError, ValueError) as e:
            self.notes.append(f"{parts[-1]} could not be sealed: {e}")

    def describe(self) -> dict[str, Any]:
        origin = self.feed.origin
        out: dict[str, Any] = {
            "file": str(self.csv.path),
            "mcap": [str(self.logs.path / p) for p in self.state.get("mcap", [])],
            "rows": self.csv.rows,
            "lost": self.feed.lost,
            "signals": self.csv.sel.labels,
            "resumed": self.resumed,
            "start_utc": origin.start_utc,
            "origin_t_s": origin.t_s,
            "urdf": str(self.urdf.path) if self.urdf.text else None,
        }
        if not self.urdf.text:
            out["urdf_missing"] = self.urdf.missing
        if self.notes:
            out["notes"] = list(self.notes)
        if self.feed.gap_lost:
            n = self.feed.gap_ticks
            out["gap"] = (
                f"{n} ticks ({n * self.feed.tel.period_s:.3f} s) lost while no command daemon ran "
                "(longer than the telemetry ring keeps); a `gap` event marks where the rows resume"
            )
        return out
