"""Reading a log back, CSV or MCAP (the same content), for `orccadctl plot` and `compare`.

Everything comes from the file itself (the CSV's header and `# event` lines; the MCAP's
channels, their units, `/events` and its metadata): a log copied elsewhere reads the same. A CSV
written before logs had a header reads without units or events. A station's log: each resource's
CSV, or the one MCAP of all (columns `left/q.<joint>`, each resource's samples at its own rate,
NaN between them).
"""

from __future__ import annotations

import csv
import json
import struct
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass
class CsvLogData:
    """A log as read back (CSV or MCAP): `data`'s first column is `time_s`, seconds since the
    log started; `events` are (time_s, kind, name), `details` the whole text of each (the
    instant's actions and states: `Home.done -> stop Home start Reach (state 1 -> 3)`)."""

    columns: list[str]
    data: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)  # start_utc, origin_t_s, robot... ({}: an old log)
    units: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (time_s, kind, name)
    details: list[str] = field(default_factory=list)  # per event: its name and detail, as logged
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)  # an MCAP's records by name


def log_parts(log: Path) -> list[Path]:
    """The files `log stop -o LOG` wrote for a station's log, where `LOG` itself is not one of them:
    LOG's stem with each resource's name (`run.left.csv`), and the station's MCAP (`run.mcap`)."""
    parts = sorted(log.parent.glob(f"{log.stem}.*{log.suffix}")) if log.suffix else []
    return [*parts, *(p for p in (log.with_suffix(".mcap"),) if p != log and p.is_file())]


def resolve_log(log: Path) -> Path:
    """`log`, or where there is no such file but a station's log under that name (`log_parts`), its
    MCAP (every resource in one file); else a `FileNotFoundError` that says which files exist."""
    if log.exists():
        return log
    parts = log_parts(log)
    mcap = log.with_suffix(".mcap")
    if mcap in parts:
        return mcap
    if parts:
        raise FileNotFoundError(
            f"{log}: no such file; this log is in {len(parts)} parts: {', '.join(str(p) for p in parts)}"
        )
    raise FileNotFoundError(f"{log}: no such file")


def is_mcap(log: Path) -> bool:
    """Whether `log` starts with MCAP's magic (`OSError` if it cannot be read)."""
    with log.open("rb") as fh:
        return fh.read(len(MCAP_MAGIC)) == MCAP_MAGIC


def read_log(log: Path) -> CsvLogData:
    """The columns, rows, header and events of a log, CSV or MCAP; `ValueError` if it is neither."""
    if is_mcap(log):
        return read_mcap(log)
    try:
        return _read_csv(log)
    except UnicodeDecodeError:
        raise ValueError(f"{log}: not an orccadd log (neither its CSV nor its MCAP)") from None


def read_mcap(log: Path) -> CsvLogData:
    """An MCAP log as its CSV reads: a column per signal group's field (`q.elbow_joint`, or the
    group's name for a scalar), the units of the channels, the events of `/events` (the name is
    the first word of the message) timed from the log's own clock. `ValueError` for a file the
    mcap reader refuses (truncated, corrupted) or without an orccadd log's signals."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    # per column its (time_s, value) pairs as they come, compact: a 10-minute log is 3 million
    # messages, which a dict per column keyed by time held in 2.6 GB
    times_of: dict[str, array[float]] = {}
    values_of: dict[str, array[float]] = {}
    units: dict[str, Any] = {"time_s": "s"}
    events: list[tuple[int, str, str, str]] = []  # (log time ns, kind, name, message)
    metadata: dict[str, dict[str, str]] = {}
    offset_ns: int | None = None  # log time − time_s, from any signal's message
    try:
        fh = log.open("rb")
    except OSError as e:
        raise ValueError(f"{log}: cannot be read ({e.strerror or e})") from None
    try:
        with fh:
            reader = make_reader(fh)
            for m in reader.iter_metadata():
                metadata[m.name] = dict(m.metadata)
            for _, channel, message in reader.iter_messages(log_time_order=False):
                body = json.loads(message.data)
                if channel.topic == "/events":
                    kind = str(body.get("name", "")).removeprefix("orccadd.")
                    text = str(body.get("message", ""))
                    name = text if text.startswith("(") else text.split(" ", 1)[0]
                    events.append((message.log_time, kind, name, text))
                    continue
                signal = channel.metadata.get("signal")
                if signal is None or "time_s" not in body:
                    continue  # /joint_states, /faults, /robot_description
                t = float(body["time_s"])
                if offset_ns is None:
                    offset_ns = message.log_time - round(t * 1e9)
                units[signal] = channel.metadata.get("unit", "?")
                for field_name, v in body.items():
                    if field_name != "time_s" and (isinstance(v, float | int) or v is None):
                        col = signal if field_name == "value" else f"{signal}.{field_name}"
                        if col not in times_of:
                            times_of[col], values_of[col] = array("d"), array("d")
                        times_of[col].append(t)
                        values_of[col].append(float("nan") if v is None else float(v))
    except (McapError, OSError, ValueError, KeyError, AttributeError, struct.error, EOFError) as e:
        why = str(e) or type(e).__name__
        why = f"truncated or corrupted (the mcap reader: {why})"
        raise ValueError(f"{log}: not a readable MCAP log: {why}") from None
    if not times_of or offset_ns is None:
        raise ValueError(f"{log}: an MCAP file without an orccadd log's signals")
    names = list(times_of)
    at = {c: np.frombuffer(times_of[c], dtype=np.float64) for c in names}
    times = np.unique(np.concatenate(list(at.values())))
    data = np.full((times.size, 1 + len(names)), np.nan)
    data[:, 0] = times
    for k, c in enumerate(names):  # a time given twice: the later value, as a dict kept it
        data[np.searchsorted(times, at[c]), k + 1] = np.frombuffer(values_of[c], dtype=np.float64)
    for group in units:  # the command's unit is its mode's, as in the CSV (a station's `left/cmd` too)
        if group.rpartition("/")[2] == "cmd":
            units[group] = {"position": "rad", "velocity": "rad/s", "torque": "N.m"}
    # to the µs, as the messages' time_s (and the CSV): an event and the tick it happened in are at one time
    timed = [(round((ns - offset_ns) * 1e-9, 6), kind, name) for ns, kind, name, _ in events]
    meta = metadata.get("orccadd.log") or {"format": "mcap"}
    return CsvLogData(["time_s", *names], data, meta, units, timed, [e[3] for e in events], metadata)


def _read_csv(log: Path) -> CsvLogData:
    meta: dict[str, Any] = {}
    units: dict[str, Any] = {}
    events: list[tuple[float, str, str]] = []
    details: list[str] = []
    columns: list[str] = []
    rows: list[list[float]] = []
    with log.open(newline="", encoding="utf-8") as fh:
        for n, line in enumerate(fh, start=1):
            try:
                if line.startswith("# orccadd log "):
                    meta = json.loads(line.removeprefix("# orccadd log "))
                elif line.startswith("# units "):
                    units = json.loads(line.removeprefix("# units "))
                elif line.startswith("# event,"):
                    ev = next(csv.reader([line]))
                    events.append((float(ev[1]), ev[3], ev[4]))
                    details.append(" ".join(ev[4:]).strip())
                elif line.startswith("#") or not line.strip():
                    continue
                elif not columns:
                    columns = next(csv.reader([line]))
                else:
                    rows.append([float(v) for v in line.split(",")])
            except (ValueError, IndexError) as e:
                raise ValueError(f"{log}:{n}: {e}") from None
    if not columns or columns[0] != "time_s" or not rows:
        raise ValueError(f"{log}: not an orccadd log (a CSV whose first column is time_s, with data rows)")
    data = np.array(rows)
    if not meta:  # an old log: absolute loop times
        data[:, 0] -= data[0, 0]
    return CsvLogData(columns, data, meta, units, events, details)
