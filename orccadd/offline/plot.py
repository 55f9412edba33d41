"""`orccadctl plot LOG -o out.png|out.svg`: one panel per signal group of a log (q, dq, tau, cmd,
...), each axis with its unit, the mission's events (automaton instants, task events, operator
commands, safe stops) as vertical marks named in a lane of their own above the panels, in as
many rows as they need not to overlap (matplotlib); legends beside the panels, not over the data.

A log is its CSV or its MCAP (the same content). Everything comes from the file itself (the
CSV's header and `# event` lines; the MCAP's channels, their units and `/events`): a log copied
elsewhere plots the same. A CSV written before logs had a header plots without units or events.
A cell's log: each resource's CSV, or the one MCAP of all (a panel per resource and signal:
`left/q`, `right/q`, each resource's samples at its own rate).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FORMATS = ("png", "svg")
MARKED = {"instant": "tab:blue", "event": "tab:red", "command": "tab:gray", "fault": "darkred"}
LANE_ROWS = 6  # rows of event names above the panels; a name that fits in none is counted, not drawn
LABEL_FONT_PT = 7
MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass
class CsvLogData:
    """A CSV log as read back."""

    columns: list[str]
    data: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)  # start_utc, origin_t_s, robot... ({}: an old log)
    units: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (time_s, kind, name)


def log_parts(log: Path) -> list[Path]:
    """The files `log stop -o LOG` wrote for a cell's log, where `LOG` itself is not one of them:
    LOG's stem with each resource's name (`run.left.csv`), and the cell's MCAP (`run.mcap`)."""
    parts = sorted(log.parent.glob(f"{log.stem}.*{log.suffix}")) if log.suffix else []
    return [*parts, *(p for p in (log.with_suffix(".mcap"),) if p != log and p.is_file())]


def resolve_log(log: Path) -> Path:
    """`log`, or where there is no such file but a cell's log under that name (`log_parts`), its
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


def read_log(log: Path) -> CsvLogData:
    """The columns, rows, header and events of a log, CSV or MCAP; `ValueError` if it is neither."""
    with log.open("rb") as fh:
        if fh.read(len(MCAP_MAGIC)) == MCAP_MAGIC:
            return read_mcap(log)
    try:
        return _read_csv(log)
    except UnicodeDecodeError:
        raise ValueError(f"{log}: not an orccadd log (neither its CSV nor its MCAP)") from None


def read_mcap(log: Path) -> CsvLogData:
    """An MCAP log as its CSV reads: a column per signal group's field (`q.elbow_joint`, or the
    group's name for a scalar), the units of the channels, the events of `/events` (the name is
    the first word of the message) timed from the log's own clock."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    columns: dict[str, dict[float, float]] = {}
    units: dict[str, Any] = {"time_s": "s"}
    events: list[tuple[int, str, str]] = []  # (log time ns, kind, name)
    meta: dict[str, Any] = {}
    offset_ns: int | None = None  # log time − time_s, from any signal's message
    try:
        with log.open("rb") as fh:
            reader = make_reader(fh)
            for m in reader.iter_metadata():
                if m.name == "orccadd.log":
                    meta = dict(m.metadata)
            for _, channel, message in reader.iter_messages():
                body = json.loads(message.data)
                if channel.topic == "/events":
                    kind = str(body.get("name", "")).removeprefix("orccadd.")
                    text = str(body.get("message", ""))
                    name = text if text.startswith("(") else text.split(" ", 1)[0]
                    events.append((message.log_time, kind, name))
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
                        columns.setdefault(col, {})[t] = float("nan") if v is None else float(v)
    except (McapError, OSError, ValueError, KeyError) as e:
        raise ValueError(f"{log}: not a readable MCAP log ({e})") from None
    if not columns or offset_ns is None:
        raise ValueError(f"{log}: an MCAP file without an orccadd log's signals")
    times = sorted({t for c in columns.values() for t in c})
    names = list(columns)
    data = np.array([[t, *(columns[c].get(t, np.nan) for c in names)] for t in times])
    for group in units:  # the command's unit is its mode's, as in the CSV (a cell's `left/cmd` too)
        if group.rpartition("/")[2] == "cmd":
            units[group] = {"position": "rad", "velocity": "rad/s", "torque": "N.m"}
    timed = [((ns - offset_ns) * 1e-9, kind, name) for ns, kind, name in events]
    return CsvLogData(["time_s", *names], data, meta or {"format": "mcap"}, units, timed)


def _read_csv(log: Path) -> CsvLogData:
    meta: dict[str, Any] = {}
    units: dict[str, Any] = {}
    events: list[tuple[float, str, str]] = []
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
    return CsvLogData(columns, data, meta, units, events)


def lane_rows(marks: list[tuple[float, str, str]], t0: float, t1: float, width_in: float) -> list[int]:
    """The lane row of each event name (-1: no room): the first row where the name starts after
    the previous one there ends, a name's width estimated from its characters at the label font
    over `width_in` inches of axis spanning [t0, t1] s."""
    span_s = max(t1 - t0, 1e-9)
    s_per_char = span_s * (LABEL_FONT_PT * 0.6 / 72.0) / width_in  # ~0.6 em a character
    ends: list[float] = []  # per row: where its last name ends, s
    out = []
    for ts, _, name in marks:
        end = ts + (len(name) + 1) * s_per_char
        row = next((i for i, e in enumerate(ends) if ts >= e), len(ends))
        if row >= LANE_ROWS:
            out.append(-1)
            continue
        if row == len(ends):
            ends.append(end)
        else:
            ends[row] = end
        out.append(row)
    return out


def axis_unit(group: str, log: CsvLogData) -> str:
    """The unit of a signal group; by mode (the command): the modes the log saw."""
    u = log.units.get(group)
    if u is None:
        return "unit not recorded" if not log.units else "?"
    if isinstance(u, dict):
        seen = list(dict.fromkeys(name for _, kind, name in log.events if kind == "mode"))
        if not seen:
            return " | ".join(dict.fromkeys(map(str, u.values()))) + " (by mode)"
        return " | ".join(dict.fromkeys(str(u.get(m, "?")) for m in seen))  # changes marked on the panel
    return str(u)


def output_format(out: Path, fmt: str | None) -> str:
    if fmt:
        if fmt not in FORMATS:
            raise ValueError(f"format {fmt!r}: one of {', '.join(FORMATS)}")
        return fmt
    suffix = out.suffix.lower().lstrip(".")
    return suffix if suffix in FORMATS else "png"


def plot_csv(log: Path, out: Path, prefixes: list[str], fmt: str | None = None) -> str:
    """Plot `log` to `out` (PNG or SVG: `fmt`, else the suffix of `out`, else PNG)."""
    form = output_format(out, fmt)
    asked, log = log, resolve_log(log)
    d = read_log(log)
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(d.columns[1:], start=1):
        base = name.split(".", 1)[0]
        # `q` names every resource's q in a cell's log (`left/q`, `right/q`); `left/q` one's
        if prefixes and base not in prefixes and base.rpartition("/")[2] not in prefixes:
            continue
        groups.setdefault(base, []).append(i)
    if not groups:
        raise ValueError(f"{log}: no column matches {prefixes} (columns: {', '.join(d.columns[1:])})")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = d.data[:, 0]
    marks = [(ts, kind, name) for ts, kind, name in d.events if kind in MARKED and t[0] <= ts <= t[-1]]
    mode_changes = [(ts, name) for ts, kind, name in d.events if kind == "mode"]
    width_in = 10.0
    rows = lane_rows(marks, float(t[0]), float(t[-1]), width_in * 0.8)
    n_rows = max(rows, default=-1) + 1
    with plt.rc_context({"svg.fonttype": "none"}):  # SVG text stays text (searchable)
        lane_in = 0.22 * max(n_rows, 1)
        fig, axes = plt.subplots(
            len(groups) + 1, 1, sharex=True, figsize=(width_in, lane_in + 2.6 * len(groups)), squeeze=False,
            gridspec_kw={"height_ratios": [lane_in, *[2.6] * len(groups)]},
        )  # fmt: skip
        lane = axes[0, 0]
        lane.set_ylim(n_rows + 0.2, -0.2)  # row 0 on top
        lane.axis("off")
        for (ts, kind, name), row in zip(marks, rows, strict=True):
            if row >= 0:
                lane.text(ts, row, name, fontsize=LABEL_FONT_PT, color=MARKED[kind], ha="left", va="center")
        axes = axes[1:]
        for ax, (base, cols) in zip(axes[:, 0], groups.items(), strict=True):
            for c in cols:  # a column's own samples (a cell's MCAP: resources at their own rates)
                y = d.data[:, c]
                has = ~np.isnan(y) if d.meta.get("resources") else slice(None)
                ax.plot(t[has], y[has], lw=1.0, label=d.columns[c].split(".", 1)[-1])
            for ts, kind, _ in marks:
                ax.axvline(ts, color=MARKED[kind], lw=0.8, ls="--", alpha=0.7)
            if isinstance(d.units.get(base), dict):  # a unit by mode: where the mode changed
                for ts, mode in mode_changes[1:]:
                    ax.axvline(ts, color="tab:green", lw=1.0, ls=":")
                    ax.text(ts, 0.95, f" {mode}", transform=ax.get_xaxis_transform(), fontsize=7,
                            color="tab:green", va="top")  # fmt: skip
            ax.set_ylabel(f"{base} [{axis_unit(base, d)}]")
            ax.grid(True, alpha=0.3)
            if len(cols) > 1:  # beside the panel: never over the data
                ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)
        axes[-1, 0].set_xlabel("time since the log started [s]" if d.meta else "time from the first row [s]")
        title = log.name + (f" (started {d.meta['start_utc']})" if d.meta.get("start_utc") else "")
        fig.suptitle(title, y=0.995)
        fig.tight_layout()
        fig.savefig(out, dpi=110, format=form)
        plt.close(fig)
    unnamed = sum(1 for r in rows if r < 0)
    skipped = f", {unnamed} not named (no room)" if unnamed else ""
    source = f" from {log} (a cell's log: every resource in its MCAP)" if log != asked else ""
    return (
        f"{out}: {len(groups)} plots, {len(d.data)} samples over {t[-1] - t[0]:.2f} s, "
        f"{len(marks)} events{skipped} ({form}){source}"
    )
