"""A logged run as `orccadctl replay` reads it: every tick's record (by its sequence number, from
the MCAP's messages), the run record, the mission's files and the parameters at start, and the
tunes applied during the run.

A replay needs the signals `log start` records by default (`orccadd.wire.commands.LOG_SIGNALS`):
a log of fewer is refused naming what it lacks. Every refusal is a `ReplayError` naming the file.
"""

from __future__ import annotations

import json
import re
import struct
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from orccadd.errors import OrccaddError
from orccadd.offline.logread import is_mcap

MISSION_RECORD = "orccadd.mission"  # orccadd/cmdd/logsession.py writes one per mission loaded

NEEDED = ("t_s", "task", "wrote", "mode", "status", "q", "dq", "tau", "cmd")
SCALARS = ("t_s", "task", "phase", "wrote", "mode", "status")
VECTORS = ("q", "dq", "tau", "cmd")
OTHER_FIELDS = ("seq", "wake_us", "compute_us")  # tick fields a replay does not read
NUMBER = r"-?(?:\d+\.?\d*(?:e[-+]?\d+)?|inf|nan)"
_TUNE = re.compile(
    r"^tune \(operator\) (?P<path>\S+): (?P<old>.+?) → (?P<new>.+?)"
    r"(?: \(first (?P<k>\d+) of (?P<n>\d+)\))? \(tick (?P<tick>\d+)\)$"
)


class ReplayError(OrccaddError):
    """A log or a request `replay` cannot take: the message names the file and why."""


@dataclass(frozen=True)
class Tune:
    """A tune as the run's log records it: applied at the start of tick `tick`."""

    tick: int
    path: str  # TASK.MODULE.PARAM or TASK.MODULE.PARAM[i]
    value: list[float]
    cut: bool  # the log kept only the first values of a longer vector

    @property
    def task(self) -> str:
        return self.path.split(".", 1)[0]


@dataclass
class RecordedRun:
    """The ticks of a run (rows in tick order, `seq` their sequence numbers) and what it ran."""

    path: Path
    meta: dict[str, str]
    joints: list[str]
    seq: np.ndarray  # int64, one per row
    scalars: dict[str, np.ndarray]  # t_s, task, phase, wrote, mode, status: one value per row
    vectors: dict[str, np.ndarray]  # q, dq, tau, cmd: rows × joints
    tasks: list[str]  # telemetry task id -> name
    mission: dict[str, str]  # the `orccadd.mission` record
    parameters: dict[str, dict[str, Any]]  # task -> MODULE.PARAM -> value, as the log started
    signals: dict[str, np.ndarray]  # the resource's own (a wrench): rows × its size
    tunes: list[Tune] = field(default_factory=list)

    @property
    def rows(self) -> int:
        return len(self.seq)

    def task_at(self, row: int) -> str:
        tid = int(self.scalars["task"][row])
        return self.tasks[tid] if 0 <= tid < len(self.tasks) else f"#{tid}"


def read_run(path: Path) -> RecordedRun:
    """The run logged in the MCAP at `path`; `ReplayError` for anything that cannot be replayed."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        if not is_mcap(path):
            raise ReplayError(f"{path}: not an MCAP file (replay reads a log's .mcap)")
        fh = path.open("rb")
    except OSError as e:
        raise ReplayError(f"{path}: cannot be read ({e.strerror or e})") from None
    # per signal: its fields, and the ticks' sequence numbers and values as they come (compact
    # arrays: a 10-minute run at 500 Hz is 3 million messages)
    fields: dict[str, list[str]] = {}
    seqs: dict[str, array[int]] = {}
    values: dict[str, array[float]] = {}
    metadata: dict[str, dict[str, str]] = {}
    missions: list[dict[str, str]] = []  # a record per mission loaded while the log ran
    raw_events: list[str] = []  # the trace's messages (the tunes among them)
    try:
        with fh:
            reader = make_reader(fh)
            for m in reader.iter_metadata():
                if m.name == MISSION_RECORD:
                    missions.append(dict(m.metadata))
                else:
                    metadata[m.name] = dict(m.metadata)
            for _, channel, message in reader.iter_messages(log_time_order=False):  # as written
                if channel.topic == "/events":
                    raw_events.append(str(json.loads(message.data).get("message", "")))
                    continue
                signal = channel.metadata.get("signal")
                if signal is None or signal in OTHER_FIELDS:
                    continue
                if "/" in signal:
                    raise ReplayError(
                        f"{path}: a station's log (signal {signal}): replay takes a one-resource robot's run"
                    )
                body = json.loads(message.data)
                names = fields.get(signal)
                if names is None:
                    if signal in SCALARS:
                        names = ["value"]
                    elif signal in VECTORS:
                        names = [k for k in body if k not in ("time_s", "mode", "unit")]
                    else:  # the resource's own: `wrench` (0..5), `speed_scaling`
                        names = [k for k in body if k == "value" or k.isdigit()]
                    fields[signal], seqs[signal], values[signal] = names, array("q"), array("d")
                seqs[signal].append(message.sequence)
                values[signal].extend([_num(body.get(k)) for k in names])
    except (McapError, OSError, ValueError, KeyError, AttributeError, struct.error, EOFError) as e:
        why = str(e) or type(e).__name__
        why = f"truncated or corrupted (the mcap reader: {why})"
        raise ReplayError(f"{path}: not a readable MCAP log: {why}") from None
    missing = [s for s in NEEDED if s not in fields]
    if missing:
        raise ReplayError(
            f"{path}: the log lacks {', '.join(missing)}: a run is replayed from a log started with "
            "`orccadctl log start` and no signal names (it records all a replay needs)"
        )
    mission = _last_mission(path, missions)
    from_tick = int(mission.get("from_tick", 0))
    joints = fields["q"]
    seq = np.unique(np.frombuffer(seqs["t_s"], dtype=np.int64))
    for k in NEEDED:  # the ticks every needed signal has
        seq = np.intersect1d(seq, np.frombuffer(seqs[k], dtype=np.int64), assume_unique=False)
    seq = seq[seq >= from_tick]
    if not seq.size:
        raise ReplayError(
            f"{path}: no tick with every signal a replay needs after mission {mission['name']} was loaded"
        )

    def column(signal: str) -> np.ndarray:
        """The signal's values at the ticks `seq` (rows × its fields; NaN where it has none)."""
        have = np.frombuffer(seqs[signal], dtype=np.int64)
        vals = np.frombuffer(values[signal], dtype=np.float64).reshape(len(have), len(fields[signal]))
        order = np.argsort(have, kind="stable")
        have, vals = have[order], vals[order]
        at = np.clip(np.searchsorted(have, seq), 0, len(have) - 1)
        out = vals[at].copy()
        out[have[at] != seq] = np.nan
        return out

    scalars = {k: column(k)[:, 0] if k in fields else np.full(seq.size, np.nan) for k in SCALARS}
    vectors = {k: column(k) for k in VECTORS}
    signals = {k: column(k) for k in fields if k not in VECTORS and k not in SCALARS}
    try:
        tasks = [str(t) for t in json.loads(mission.get("tasks", "[]"))]
        parameters = {str(t): dict(v) for t, v in json.loads(mission.get("parameters", "{}")).items()}
    except (ValueError, TypeError, AttributeError) as e:
        raise ReplayError(f"{path}: the record of mission {mission['name']} cannot be read ({e})") from None
    meta = metadata.get("orccadd.log", {})
    run = RecordedRun(path, meta, joints, seq, scalars, vectors, tasks, mission, parameters, signals)
    for text in raw_events:
        t = _TUNE.match(text)
        if t:
            run.tunes.append(Tune(int(t["tick"]), t["path"], _values(t["new"]), t["k"] is not None))
    return run


def _last_mission(path: Path, missions: list[dict[str, str]]) -> dict[str, str]:
    """The record of the last mission loaded while the log ran (replay takes its runs)."""
    if not missions:
        raise ReplayError(
            f"{path}: the log carries no mission (none was loaded while it ran, or an older log)"
        )
    m = missions[-1]
    if "mission" not in m:
        why = m.get("unreadable") or "its file was not read"
        raise ReplayError(f"{path}: mission {m.get('name', '?')} cannot be read from the log ({why})")
    return m


def _num(v: Any) -> float:
    return float("nan") if v is None else float(v)


def _values(text: str) -> list[float]:
    return [float(x) for x in text.strip("[]").split(",")]
