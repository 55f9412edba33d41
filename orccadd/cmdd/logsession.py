"""One log, from `log start` to `log stop`: the CSV and its MCAP part(s) beside it, fed from the
same records (`LogFeed`), described in the state file so that the command daemon started after
one died carries it on (`resume`): the CSV from its last complete row, the MCAP in a new part
(the unfinished one sealed), the same time origin, the gap filled from the telemetry ring.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from orccadd import __version__
from orccadd.cmdd.csvlog import CsvLog, LogDir
from orccadd.cmdd.logfeed import Decoder, LogFeed, LogOrigin
from orccadd.cmdd.mcaplog import McapLog, McapStream, Urdf, seal
from orccadd.cmdd.views import SignalSelection
from orccadd.wire import foxglove_schemas as sch
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


def csv_name(name: str, resource: str) -> str:
    """A log's CSV: `run.csv` itself, or in a station each resource's `run.<resource>.csv`."""
    return f"{name.removesuffix('.csv')}.{resource}.csv" if resource else name


@dataclass(frozen=True)
class LogSource:
    """What a log records of one resource: its name ("" in a one-resource robot), telemetry
    block and signals."""

    resource: str
    tel: TelemetryBlock
    selection: SignalSelection


@dataclass
class Stream:
    """One resource's part of a log: its CSV (rows at its own rate) and what feeds it."""

    resource: str
    feed: LogFeed
    csv: CsvLog


class TelemetryLog:
    """Chosen signals at full rate into `<name>.csv` and `<name>.mcap`, events in both. A station's
    log: a CSV per resource (`<name>.<resource>.csv`, its own rate, its columns named by it) and
    one MCAP of every resource; the events (the trace, in the daemon's own block) in each."""

    def __init__(
        self,
        logs: LogDir,
        streams: list[Stream],
        state: dict[str, Any],
        urdf: Urdf,
        resumed: bool,
    ) -> None:
        self.logs = logs
        self.streams = streams
        self.state = state
        self.urdf = urdf
        self.resumed = resumed
        self.mcap: McapLog | None = None
        self.notes: list[str] = []

    @property
    def csv(self) -> CsvLog:
        return self.streams[0].csv

    @property
    def feed(self) -> LogFeed:
        return self.streams[0].feed

    @property
    def path(self) -> Path:
        return self.csv.path

    @staticmethod
    def start(
        logs: LogDir,
        sources: list[LogSource],
        trace: TelemetryBlock,
        name: str,
        desc: Callable[[], dict[str, Any]],
        decode: Decoder,
        urdf_path: Path | None,
        extra_state: dict[str, Any],
    ) -> TelemetryLog:
        """A new log from the next tick; `ValueError` if its files cannot be created."""
        origins = [LogOrigin.now(s.tel) for s in sources]
        for s, origin in zip(sources, origins, strict=True):
            if origin.tick == 0:
                who = f"resource {s.resource}'s" if s.resource else "the"
                raise ValueError(f"log: {who} control loop has not ticked yet: no time to start the log from")
        trace_start = int(trace.header[H.TRACE_HEAD])
        created: list[str] = []
        streams: list[Stream] = []
        try:
            for s, origin in zip(sources, origins, strict=True):
                file = csv_name(name, s.resource)
                mission = desc().get("mission") or {}  # the loaded one when the log starts
                meta = {
                    "robot": desc().get("robot"),
                    "period_s": s.tel.period_s,
                    "mission": mission.get("name", ""),
                    "mission_deployment": mission.get("deployment", ""),
                }
                if s.resource:
                    meta["resource"] = s.resource
                fh = logs.create(file)
                created.append(file)
                csv = CsvLog(fh, logs.path / file, s.selection, origin, meta)
                events = trace if not streams else None  # the first stream carries the events
                streams.append(Stream(s.resource, LogFeed(s.tel, origin, decode, origin.tick, events), csv))
            mcap_fd = logs.create_fd(part_name(name, 1))
            created.append(part_name(name, 1))
        except ValueError:
            for st in streams:
                st.csv.close()
            for file in created:
                logs.remove(file)
            raise
        state = {
            **extra_state,
            "file": name,
            "streams": [
                {
                    "resource": st.resource,
                    "csv": st.csv.path.name,
                    "signals": st.csv.sel.labels,
                    "tick_signals": st.csv.sel.signals,
                    "origin": st.feed.origin.to_state(),
                }
                for st in streams
            ],
            "trace_start": trace_start,
            "mcap": [part_name(name, 1)],
        }
        state["missions"] = []  # `add_mission`'s records, written again into each new part
        rec = TelemetryLog(logs, streams, state, Urdf.read(urdf_path), resumed=False)
        try:
            rec._open_mcap(os.fdopen(mcap_fd, "wb"), 1, desc, 0.0)
        except OSError as e:
            for st in streams:
                st.csv.close()
            for file in created:
                logs.remove(file)
            raise ValueError(f"log: cannot write {part_name(name, 1)}: {e.strerror or e}") from None
        return rec

    @staticmethod
    def resume(
        logs: LogDir,
        blocks: dict[str, tuple[TelemetryBlock, list[str]]],
        trace: TelemetryBlock,
        state: dict[str, Any],
        desc: Callable[[], dict[str, Any]],
        decode: Decoder,
        urdf_path: Path | None,
    ) -> TelemetryLog:
        """The log of `state` carried on after each CSV's last complete row, `blocks` giving each
        resource's telemetry block and joints ("": a one-resource robot's), `trace` the daemon's
        block (its events) (`KeyError`,
        `ValueError`, `OSError`... if it cannot be)."""
        streams: list[Stream] = []
        last_s: list[float] = []
        try:
            for k, entry in enumerate(state["streams"]):
                resource = str(entry["resource"])
                tel, joints = blocks[resource]
                own = entry.get("tick_signals", [])
                sel = SignalSelection([str(s) for s in entry["signals"]], joints, resource, own)
                origin = LogOrigin.from_state(entry["origin"])
                fh, tail = logs.reopen(str(entry["csv"]))
                last = tail.last_time_s
                after_tick = origin.tick if last == float("-inf") else tick_at(tel, origin.t_s + last)
                after_trace = max(tail.last_event_seq, int(state["trace_start"])) if k == 0 else None
                feed = LogFeed(tel, origin, decode, after_tick, trace if k == 0 else None, after_trace)
                csv = CsvLog(fh, logs.path / str(entry["csv"]), sel, origin, rows=tail.rows)
                streams.append(Stream(resource, feed, csv))
                last_s.append(max(last, 0.0))
        except BaseException:
            for st in streams:
                st.csv.close()
            raise
        rec = TelemetryLog(logs, streams, dict(state), Urdf.read(urdf_path), resumed=True)
        rec._next_part(desc, last_s[0])
        return rec

    def _next_part(self, desc: Callable[[], dict[str, Any]], from_s: float) -> None:
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
                self._open_mcap(os.fdopen(fd, "wb"), n, desc, from_s)
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

    def _open_mcap(self, fh: Any, part: int, desc: Callable[[], dict[str, Any]], from_s: float) -> None:
        origin = self.feed.origin
        parts = self.state["mcap"]
        info = {
            "csv": ",".join(st.csv.path.name for st in self.streams),
            "part": part,
            "continues": parts[-2] if part > 1 and len(parts) > 1 else "",
            "start_utc": origin.start_utc,
            "origin_t_s": repr(origin.t_s),
            "origin_tick": origin.tick,
            "robot": desc().get("robot"),
            "period_s": self.feed.tel.period_s,
            "signals": ",".join(label for st in self.streams for label in st.csv.sel.labels),
            "urdf": str(self.urdf.path) if self.urdf.text else f"none: {self.urdf.missing}",
            **run_record(desc()),
        }
        if len(self.streams) > 1:
            info["resources"] = ",".join(st.resource for st in self.streams)
            info["periods_s"] = ",".join(repr(st.feed.tel.period_s) for st in self.streams)
        path = self.logs.path / parts[-1]
        try:
            records = [(MISSION_RECORD, r) for r in self.state.get("missions") or []]
            self.mcap = McapLog(fh, path, self._mcap_streams(), info, self.urdf, desc, from_s, records)
        except Exception:
            with contextlib.suppress(OSError):
                fh.close()
            raise

    def _mcap_streams(self) -> list[McapStream]:
        """Each stream's joints as `/joint_states` names them: a joint name two resources share
        (two identical arms) is told apart by its resource's (`left/elbow_joint`)."""
        names = [st.csv.sel.joints for st in self.streams]
        seen = [j for js in names for j in js]
        return [
            McapStream(
                st.csv.sel,
                [sch.joint_state_name(st.resource, j, seen) for j in js],
                st.feed.origin,
                st.feed.tel.period_s,
            )
            for st, js in zip(self.streams, names, strict=True)
        ]

    @property
    def mission_generation(self) -> int:
        """The generation of the last mission `add_mission` recorded (-1: none)."""
        missions = self.state.get("missions") or []
        return int(missions[-1]["generation"]) if missions else -1

    def add_mission(self, record: dict[str, str]) -> None:
        """A mission loaded (or loaded when the log started): its record (`mission_record`) into
        the MCAP's metadata, and into every part after this one."""
        self.state.setdefault("missions", []).append(record)
        if self.mcap is not None:
            self.mcap.add_metadata(MISSION_RECORD, record)

    # ---- running ----------------------------------------------------------------------------
    def pump(self) -> None:
        """Write the new ticks and events: the MCAP first, so that a command daemon dying in
        between leaves the parts overlapping rather than a hole (`OSError` naming the file if
        one cannot take them). The first stream's events (the mission's trace) go to every CSV;
        a stream's changes of command mode to its own."""
        polled = [st.feed.poll() for st in self.streams]
        shared = [e for e in polled[0][1] if e.kind != "mode"]
        for k, (st, (recs, events)) in enumerate(zip(self.streams, polled, strict=True)):
            own = events if k == 0 else sorted(shared + events, key=lambda e: e.time_s)
            self._write(self._mcap_path(), self._mcap_write, recs, events, k)
            self._write(st.csv.path, st.csv.write, recs, own)

    @staticmethod
    def _write(path: Path | None, write: Callable[..., None], *args: Any) -> None:
        try:
            write(*args)
        except OSError as e:
            raise OSError(e.errno, f"{e.strerror or e} ({path})") from e
        except Exception as e:  # a bug in a writer must not stop the command daemon's pump
            raise OSError(f"{type(e).__name__}: {e} ({path})") from e

    def size_bytes(self) -> int:
        """What the log's files hold so far (the CSVs and the MCAP part being written)."""
        mcap = self.mcap.fh.tell() if self.mcap is not None else 0
        return sum(st.csv.size for st in self.streams) + int(mcap)

    def _mcap_path(self) -> Path | None:
        return self.mcap.path if self.mcap else None

    def _mcap_write(self, recs: Any, events: Any, stream: int) -> None:
        if self.mcap is not None:
            self.mcap.write(recs, events, stream)

    @property
    def rows(self) -> int:
        return sum(st.csv.rows for st in self.streams)

    @property
    def lost(self) -> int:
        return sum(st.feed.lost for st in self.streams)

    def close(self, reason: str = "log stop", result: str = "") -> dict[str, Any]:
        """The end: `reason` why, `result` the last run's as the log ends (`MissionResult`)."""
        self.pump()
        summary = self.describe()
        if self.mcap is not None:
            end = {"rows": self.rows, "lost": self.lost, "ended": reason, "result": result}
            self.mcap.close(end)
        for st in self.streams:
            st.csv.close()
        return summary

    def abandon(self, error: OSError) -> dict[str, Any]:
        """A file failed (a full disk): close what can be closed, leave every file readable (the
        CSV ends with its last complete row: `CsvLog`; the MCAP part sealed, or removed if it holds
        nothing) and say why the log ended."""
        for st in self.streams:
            with contextlib.suppress(OSError, ValueError):
                st.csv.close()
        if self.mcap is not None:
            self.mcap.abandon()
            self.mcap = None
            self._seal_last_part("sealed after the write error (readable to its last record)")
        reason = error.strerror or str(error)
        return {**self.describe(), "error": f"log ended: {reason} after {self.rows} rows"}

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
            "rows": self.rows,
            "lost": self.lost,
            "signals": [label for st in self.streams for label in st.csv.sel.labels],
            "resumed": self.resumed,
            "start_utc": origin.start_utc,
            "origin_t_s": origin.t_s,
            "urdf": str(self.urdf.path) if self.urdf.text else None,
        }
        if self.streams[0].resource:  # a station: a CSV per resource
            out["name"] = str(self.logs.path / str(self.state["file"]))
            out["files"] = [str(st.csv.path) for st in self.streams]
            out["resources"] = {
                st.resource: {"file": str(st.csv.path), "rows": st.csv.rows, "lost": st.feed.lost}
                for st in self.streams
            }
        if not self.urdf.text:
            out["urdf_missing"] = self.urdf.missing
        if self.notes:
            out["notes"] = list(self.notes)
        gaps = [st for st in self.streams if st.feed.gap_lost]
        if gaps:
            n = gaps[0].feed.gap_ticks
            out["gap"] = (
                f"{n} ticks ({n * gaps[0].feed.tel.period_s:.3f} s) lost while no command daemon ran "
                "(longer than the telemetry ring keeps); a `gap` event marks where the rows resume"
            )
        return out


def run_record(desc: dict[str, Any]) -> dict[str, str]:
    """What identifies the run a log records (its MCAP's `orccadd.log` metadata, for `compare`):
    the mission loaded when it starts and its deployment hash (orccadd/daemon/deploy.py), the
    robot config and its file's sha256, the orccadd version."""
    mission = desc.get("mission") or {}
    config = str(desc.get("config") or "")
    try:
        config_sha = hashlib.sha256(Path(config).read_bytes()).hexdigest() if config else ""
    except OSError as e:
        config_sha = f"unreadable: {e.strerror or e}"
    return {
        "mission": str(mission.get("name", "")),
        "mission_file": str(mission.get("file", "")),
        "mission_deployment": str(mission.get("deployment", "")),
        "config": config,
        "config_sha256": config_sha,
        "orccadd_version": __version__,
    }


MISSION_RECORD = "orccadd.mission"  # a metadata record per mission a log saw loaded
MISSION_FILE_MAX_BYTES = 1 << 20
MISSION_FILES_MAX = 64
FROM_RE = re.compile(r'\bfrom\s+"([^"\n]*)"')  # a task's file in a mission (as the compiler reads it)


def mission_record(
    desc: dict[str, Any], parameters: dict[str, dict[str, Any]], from_tick: int
) -> dict[str, str]:
    """What `orccadctl replay` needs of the mission loaded (`desc`): its name, file and
    generation, the tick from which the telemetry's task ids are its (`from_tick`) and those
    tasks by id (`tasks`), its text and every task file's (`mission`, `task:<ref>` per file as it
    names them; a file that cannot be read in `unreadable`), and every task's parameters at that
    moment (`parameters`: JSON, by task, `MODULE.PARAM` → value)."""
    mission = desc.get("mission") or {}
    path = str(mission.get("file") or "")
    rec = {
        "name": str(mission.get("name", "")),
        "file": path,
        "deployment": str(mission.get("deployment", "")),
        "generation": str(desc.get("generation", -1)),
        "from_tick": str(from_tick),
        "tasks": json.dumps(desc.get("tasks") or []),
        "parameters": json.dumps(parameters, separators=(",", ":")),
    }
    unreadable: list[str] = []

    def read(p: Path, what: str) -> str | None:
        try:
            with p.open("rb") as fh:
                data = fh.read(MISSION_FILE_MAX_BYTES + 1)
            if len(data) > MISSION_FILE_MAX_BYTES:
                unreadable.append(f"{what}: larger than {MISSION_FILE_MAX_BYTES} bytes")
                return None
            return data.decode("utf-8")
        except (OSError, UnicodeDecodeError) as e:
            unreadable.append(f"{what}: {getattr(e, 'strerror', None) or e}")
            return None

    text = read(Path(path), path) if path else None
    if text is not None:
        rec["mission"] = text
        for ref in list(dict.fromkeys(FROM_RE.findall(text)))[:MISSION_FILES_MAX]:
            f = Path(ref) if Path(ref).is_absolute() else Path(path).parent / ref
            body = read(f, ref)
            if body is not None:
                rec[f"task:{ref}"] = body
    if unreadable:
        rec["unreadable"] = "; ".join(unreadable)
    return rec
