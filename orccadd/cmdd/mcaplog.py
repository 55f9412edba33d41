"""The MCAP file of a log, beside its CSV (same base name), for Foxglove, PlotJuggler or any MCAP
reader: every signal group of the selection as a JSON channel whose schema gives its unit
(`orccadd.wire.foxglove_schemas`), `/joint_states` (foxglove.JointStates: all joints, at most
`JOINT_STATES_HZ`),
`/events` (foxglove.Log: automaton instants, task events, operator commands, safe stops, mode
changes), `/faults` (orccadd.StopCause: each safe stop's cause, typed),
`/robot_description` (the URDF as text, once), the URDF file attached, and the log's start and
end as metadata records. Log times are wall-clock ns: the log's start plus `time_s`.

A chunk is written at every pump, so a command daemon that dies loses at most the pump it died
in. MCAP cannot be appended to (its index ends the file): the next command daemon seals the part
left unfinished (`seal`: cut after its last complete record, then a footer without index, which
every reader reads linearly) and carries the log on in a new part, `<name>-2.mcap`.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import DataEnd, Footer, Header
from mcap.writer import Writer

from orccadd import __version__
from orccadd.cmdd.logfeed import MODE_UNITS, FloatArray, LogEvent, LogOrigin, base_signal, mode_name, unit
from orccadd.cmdd.views import SignalSelection
from orccadd.wire import foxglove_schemas as sch
from orccadd.wire.schema import CommandMode, Phase, T, TickLayout, status_names

MAGIC = b"\x89MCAP0\r\n"
FOOTER_BYTES = 1 + 8 + 20  # opcode, length, summary start and offset start, crc
# No chunks: every record goes to the file as it is written, so a crash loses nothing written
# before it (the writer's public API cannot end a chunk at will; a chunk being built would be
# lost). The cost: no compression (about the CSV's size); the index is still written at the end.
JOINT_STATES_HZ = 50.0  # enough for the 3D panel; q, dq and tau are also in full on their channels
URDF_MAX_BYTES = 8 << 20
LIBRARY = f"orccadd {__version__}"


@dataclass(frozen=True)
class Urdf:
    """The robot description a log attaches (or why it has none)."""

    path: Path | None
    text: str = ""
    missing: str = ""  # why there is none

    @staticmethod
    def read(path: Path | None) -> Urdf:
        if path is None:
            return Urdf(None, missing="the command daemon was not told the robot's URDF")
        try:
            with path.open("rb") as fh:
                data = fh.read(URDF_MAX_BYTES + 1)
            if len(data) > URDF_MAX_BYTES:
                return Urdf(path, missing=f"{path} is larger than {URDF_MAX_BYTES} bytes")
            return Urdf(path, data.decode("utf-8"))
        except (OSError, UnicodeDecodeError) as e:
            return Urdf(path, missing=f"cannot read {path}: {e}")


class _Group:
    """One signal group of the selection: its channel, the record columns of its fields and the
    text of its messages (formatted, not `json.dumps`'d: a tick's messages cost ~4x less so)."""

    def __init__(self, channel: int, name: str, fields: list[str], cols: list[int]) -> None:
        self.channel = channel
        self.name = name  # the tick field (`q`), whatever the channel's resource
        self.fields = fields
        self.cols = cols
        self.head = '{"time_s": %.6f' + "".join(f", {json.dumps(f)}: %r" for f in fields)

    def text(self, t_s: float, vals: list[float], extra: str) -> bytes:
        """The message (every value finite: `repr` of a float is JSON)."""
        return (self.head % (t_s, *[vals[c] for c in self.cols]) + extra + "}").encode()

    def json_text(self, t_s: float, vals: list[float], extra: str) -> bytes:
        """The message when a value is NaN or infinite (JSON null)."""
        msg = {"time_s": round(t_s, 6)} | {
            f: _clean(vals[c]) for f, c in zip(self.fields, self.cols, strict=True)
        }
        return (json.dumps(msg)[:-1] + extra + "}").encode()


@dataclass(frozen=True)
class McapStream:
    """One resource's ticks in a log's MCAP: what is sampled, the names its joints take on
    `/joint_states`, its time origin (each resource's clock has its own) and period."""

    selection: SignalSelection
    joint_names: list[str]
    origin: LogOrigin
    period_s: float


class _Source:
    """A stream as written: its channels and when it last sent `/joint_states`."""

    def __init__(self, stream: McapStream, groups: list[_Group]) -> None:
        self.origin = stream.origin
        self.joints = stream.joint_names
        self.layout = TickLayout(len(stream.joint_names))
        period_s = stream.period_s
        self.every = max(1, round(1.0 / (JOINT_STATES_HZ * period_s))) if period_s > 0 else 1
        self.groups = groups


class McapLog:
    """A log's MCAP part: `write` the feed's records and events, `close` at the end. A station's
    resources are streams of it: their channels named by resource (`/left/q`), every joint on
    the one `/joint_states`, the events (`/events`, `/faults`) once, timed on the first's clock."""

    def __init__(
        self,
        fh: IO[bytes],
        path: Path,
        streams: list[McapStream],
        info: dict[str, Any],
        urdf: Urdf,
        desc: Callable[[], dict[str, Any]],
        from_time_s: float = 0.0,
        records: list[tuple[str, dict[str, str]]] | None = None,
    ) -> None:
        """A new part; `info` goes into its `orccadd.log` metadata, `records` into metadata records
        of their own (the mission's files, the parameters at start); `from_time_s`: where it starts."""
        self.fh = fh
        self.path = path
        self.origin = streams[0].origin
        self.desc = desc
        w = self.writer = Writer(fh, use_chunking=False)
        w.start(profile="", library=LIBRARY)
        w.add_metadata("orccadd.log", {k: str(v) for k, v in info.items()})
        for name, record in records or []:
            w.add_metadata(name, {k: str(v) for k, v in record.items()})
        self.sources = [_Source(s, self._register_groups(s.selection)) for s in streams]
        self.joint_states = w.register_channel(
            "/joint_states",
            "json",
            w.register_schema("foxglove.JointStates", "jsonschema", sch.JOINT_STATES_SCHEMA),
        )
        self.events = w.register_channel(
            "/events", "json", w.register_schema("foxglove.Log", "jsonschema", sch.LOG_SCHEMA)
        )
        self.faults = w.register_channel(
            "/faults", "json", w.register_schema("orccadd.StopCause", "jsonschema", sch.STOP_CAUSE_SCHEMA)
        )
        start_ns = self.origin.wall_ns_at(from_time_s)
        if urdf.text and urdf.path is not None:
            w.add_attachment(start_ns, start_ns, urdf.path.name, "application/xml", urdf.text.encode())
            desc_ch = w.register_channel(
                "/robot_description",
                "json",
                w.register_schema("std_msgs/msg/String", "jsonschema", sch.STRING_SCHEMA),
                {"source": str(urdf.path)},
            )
            w.add_message(desc_ch, start_ns, json.dumps({"data": urdf.text}).encode(), start_ns)
        self._end_chunk()

    def _register_groups(self, sel: SignalSelection) -> list[_Group]:
        w = self.writer
        by_name: dict[str, tuple[list[str], list[int]]] = {}
        for label, col in zip(sel.labels, sel.cols, strict=True):
            base, _, joint = label.partition(".")
            fields, cols = by_name.setdefault(base, ([], []))
            fields.append(joint or "value")
            cols.append(col)
        groups = []
        for name, (fields, cols) in by_name.items():
            signal = base_signal(name)
            u = sel.units.get(signal) or unit(name)
            schema = w.register_schema(f"orccadd.{signal}", "jsonschema", sch.group_schema(signal, fields, u))
            ch = w.register_channel(f"/{name}", "json", schema, {"signal": name, "unit": u})
            groups.append(_Group(ch, signal, fields, cols))
        return groups

    def write(self, recs: FloatArray, events: list[LogEvent], stream: int = 0) -> None:
        """A stream's new records, and events, in one chunk (`OSError` if the file cannot take them)."""
        finite = bool(np.isfinite(recs).all())
        src = self.sources[stream]
        for rec in recs:
            self._tick(src, rec.tolist(), finite)
        for e in events:
            self._event(e)
        self._end_chunk()

    def _tick(self, src: _Source, vals: list[float], finite: bool) -> None:
        t = vals[T.T_S] - src.origin.t_s
        ns = src.origin.wall_ns_at(t)
        seq = int(vals[T.SEQ]) % 2**32
        add = self.writer.add_message
        for g in src.groups:
            extra = self._extra(g.name, vals)
            data = g.text(t, vals, extra) if finite else g.json_text(t, vals, extra)
            add(g.channel, ns, data, ns, seq)
        if seq % src.every == 0:
            at = src.layout
            q, dq, tau = vals[at.q], vals[at.dq], vals[at.tau]
            joints = [
                {"name": name, "position": _clean(q[j]), "velocity": _clean(dq[j]), "effort": _clean(tau[j])}
                for j, name in enumerate(src.joints)
            ]
            data = json.dumps({"timestamp": sch.stamp(ns), "joints": joints}).encode()
            add(self.joint_states, ns, data, ns, seq)

    def _extra(self, group: str, vals: list[float]) -> str:
        """The fields a group's message has beyond its values (names of ids, `cmd`'s unit)."""
        if group == "cmd":
            mode = int(vals[T.MODE])
            u = MODE_UNITS[CommandMode(mode)] if mode in MODE_UNITS else "?"
            return f', "mode": "{mode_name(mode)}", "unit": "{u}"'
        if group == "task":
            tasks = self.desc().get("tasks", [])
            tid = int(vals[T.TASK])
            return f', "name": {json.dumps(tasks[tid] if 0 <= tid < len(tasks) else f"#{tid}")}'
        if group == "phase":
            p = int(vals[T.PHASE])
            return f', "name": "{Phase(p).name.lower() if p in Phase._value2member_map_ else f"#{p}"}"'
        if group == "mode":
            return f', "name": "{mode_name(vals[T.MODE])}"'
        if group == "status":
            return f', "flags": {json.dumps(status_names(int(vals[T.STATUS])))}'
        return ""

    def _event(self, e: LogEvent) -> None:
        ns = self.origin.wall_ns_at(e.time_s)
        msg = {
            "timestamp": sch.stamp(ns),
            "level": sch.level(e.kind, e.name, e.exception),
            "message": f"{e.name} {e.detail}".strip(),
            "name": f"orccadd.{e.kind}",
            "file": "",
            "line": max(e.seq, 0),
        }
        self.writer.add_message(self.events, ns, json.dumps(msg).encode(), ns, max(e.seq, 0))
        if e.kind == "command" and e.name == "tune":  # and in the run record's metadata
            self.writer.add_metadata("orccadd.tune", {"time_s": f"{e.time_s:.6f}", "tune": e.detail})
        if e.fault is not None:
            cause = {"timestamp": sch.stamp(ns), **e.fault}
            self.writer.add_message(self.faults, ns, json.dumps(cause).encode(), ns, max(e.seq, 0))

    def add_metadata(self, name: str, record: dict[str, str]) -> None:
        """A metadata record, now (`OSError` if the file cannot take it)."""
        self.writer.add_metadata(name, record)
        self._end_chunk()

    def _end_chunk(self) -> None:
        """What the writer has finished (whole chunks) to the file."""
        self.fh.flush()

    def close(self, summary: dict[str, Any]) -> None:
        """The end metadata, the index, the footer; closes the file."""
        try:
            self.writer.add_metadata("orccadd.log.end", {k: str(v) for k, v in summary.items()})
            self.writer.finish()  # type: ignore[no-untyped-call]
        finally:
            self.fh.close()

    def abandon(self) -> None:
        with contextlib.suppress(OSError, ValueError):
            self.fh.close()


def _clean(v: Any) -> float | None:
    """A number for JSON: NaN and infinities (not JSON) become null."""
    f = float(v)
    return f if math.isfinite(f) else None


def seal(fd: int) -> bool:
    """Make an MCAP file cut short readable: cut it after its last complete record and end it
    with a footer without index (readers then read it linearly); a complete file is left as it
    is. False if it was complete. On a full disk, records are given up from the end until the
    footer fits (cutting frees what they held)."""
    size = os.fstat(fd).st_size
    if os.pread(fd, 8, 0) != MAGIC:
        raise ValueError("not an MCAP file")
    footer_at = size - 8 - FOOTER_BYTES
    if (
        footer_at > 8
        and os.pread(fd, 1, footer_at) == bytes([Opcode.FOOTER])
        and os.pread(fd, 8, size - 8) == MAGIC
    ):
        return False  # finished: nothing to seal
    ends = [8]  # where each complete record ends (the first: after the magic)
    data_end = False
    while ends[-1] + 9 <= size:
        op, length = struct.unpack("<BQ", os.pread(fd, 9, ends[-1]))
        end = ends[-1] + 9 + length
        if end > size or op == Opcode.FOOTER:
            break
        ends.append(end)
        if op == Opcode.DATA_END:
            data_end = True  # the summary after it may be cut short: end the file here
            break
    while True:
        pos = ends[-1]
        b = RecordBuilder()
        if len(ends) == 1:
            Header(profile="", library=LIBRARY).write(b)
        if not data_end:
            DataEnd(data_section_crc=0).write(b)
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(b)
        tail = bytes(b.end()) + MAGIC  # type: ignore[no-untyped-call]
        os.ftruncate(fd, pos)
        try:
            if os.pwrite(fd, tail, pos) == len(tail):
                return True
        except OSError as e:
            if e.errno != errno.ENOSPC or len(ends) == 1:
                raise
        ends.pop()  # no room: give up the last record too
        data_end = False
