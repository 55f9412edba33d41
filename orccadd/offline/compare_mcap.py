"""`orccadctl compare A B --mcap cmp.mcap`: both runs in one MCAP file that Foxglove overlays:
each run's signal groups on `/a/<group>` and `/b/<group>` (the same JSON messages and units as
the logs': `time_s` and a field per joint, so a plot panel takes `/a/q.elbow_joint` and
`/b/q.elbow_joint` side by side) and its events on `/a/events`, `/b/events` (foxglove.Log).
The two runs share one time axis, aligned on each mission's first instant (its `start`), so a
task that ran longer in one run shows where the other had moved on."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from orccadd import __version__
from orccadd.offline.runs import Run
from orccadd.wire import foxglove_schemas as sch


def write_overlay(a: Run, b: Run, out: Path) -> str:
    """Write `out` (replacing it); a line saying what it holds."""
    t0 = max(a.instants[0].time_s, b.instants[0].time_s)  # both missions start at t0 on the shared axis
    base_ns = _start_ns(a)
    messages = 0
    with out.open("wb") as fh:
        w = Writer(fh)
        w.start(profile="", library=f"orccadd {__version__} compare")
        w.add_metadata(
            "orccadd.compare", {"a": str(a.path), "b": str(b.path), "aligned_on": "the first instant"}
        )
        log_schema = w.register_schema("foxglove.Log", "jsonschema", sch.LOG_SCHEMA)
        for prefix, run in (("a", a), ("b", b)):
            shift_s = t0 - run.instants[0].time_s
            messages += _signals(w, prefix, run, base_ns, shift_s)
            ch = w.register_channel(f"/{prefix}/events", "json", log_schema)
            for (t, kind, name), text in zip(run.log.events, run.log.details, strict=True):
                ns = base_ns + round((t + shift_s) * 1e9)
                lvl = sch.level(kind, name, 3 if kind == "fault" else 0)
                msg = {"timestamp": sch.stamp(ns), "level": lvl, "message": text,
                       "name": f"orccadd.{kind}", "file": str(run.path.name), "line": 0}  # fmt: skip
                w.add_message(ch, ns, json.dumps(msg).encode(), ns)
                messages += 1
        w.finish()  # type: ignore[no-untyped-call]
    return f"{out}: both runs on /a/... and /b/..., {messages} messages, aligned on the missions' start"


def _start_ns(r: Run) -> int:
    """A's wall-clock start (its header's `start_utc`), or 0 where it has none."""
    try:
        return int(datetime.fromisoformat(str(r.log.meta["start_utc"])).astimezone(UTC).timestamp() * 1e9)
    except (KeyError, ValueError):
        return 0


def _signals(w: Writer, prefix: str, r: Run, base_ns: int, shift_s: float) -> int:
    """A channel per signal group of `r` under `/prefix/`; the messages written."""
    groups: dict[str, list[tuple[str, int]]] = {}
    for i, name in enumerate(r.log.columns[1:], start=1):
        base, _, joint = name.partition(".")
        groups.setdefault(base, []).append((joint or "value", i))
    data = r.log.data
    n = 0
    for group, cols in groups.items():
        unit = r.log.units.get(group, "?")
        unit_text = sch.CMD_UNIT if isinstance(unit, dict) else str(unit)
        fields = [f for f, _ in cols]
        schema = w.register_schema(
            f"orccadd.{group}", "jsonschema", sch.group_schema(group, fields, unit_text)
        )
        ch = w.register_channel(f"/{prefix}/{group}", "json", schema, {"signal": group, "unit": unit_text})
        idx = [c for _, c in cols]
        for row in data[np.isfinite(data[:, idx]).any(axis=1)]:
            t = float(row[0]) + shift_s
            ns = base_ns + round(t * 1e9)
            if ns < 0:
                continue
            msg = {"time_s": round(t, 6)} | {f: _val(row[c]) for f, c in cols}
            w.add_message(ch, ns, json.dumps(msg).encode(), ns)
            n += 1
    return n


def _val(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None
