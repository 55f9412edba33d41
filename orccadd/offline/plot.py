"""`orccadctl plot LOG -o out.png|out.svg`: one panel per signal group of a CSV log (q, dq, tau,
cmd, ...), each axis with its unit, the mission's events (automaton instants, task events,
operator commands) as named vertical marks (matplotlib).

Everything comes from the CSV itself (its header's units, its `# event` lines): a log copied
elsewhere plots the same. A log written before logs had a header plots without units or events.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FORMATS = ("png", "svg")
MARKED = {"instant": "tab:blue", "event": "tab:red", "command": "tab:gray"}  # kinds drawn, colours
MAX_LABELS = 60  # event names written on the figure (every event is marked)


@dataclass
class CsvLogData:
    """A CSV log as read back."""

    columns: list[str]
    data: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)  # start_utc, origin_t_s, robot... ({}: an old log)
    units: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (time_s, kind, name)


def read_log(log: Path) -> CsvLogData:
    """The columns, rows, header and events of a CSV log; `ValueError` if it is not one."""
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
    d = read_log(log)
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(d.columns[1:], start=1):
        base = name.split(".", 1)[0]
        if prefixes and base not in prefixes:
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
    with plt.rc_context({"svg.fonttype": "none"}):  # SVG text stays text (searchable)
        fig, axes = plt.subplots(len(groups), 1, sharex=True, figsize=(10, 2.6 * len(groups)), squeeze=False)
        for ax, (base, cols) in zip(axes[:, 0], groups.items(), strict=True):
            for c in cols:
                ax.plot(t, d.data[:, c], lw=1.0, label=d.columns[c].split(".", 1)[-1])
            for ts, kind, _ in marks:
                ax.axvline(ts, color=MARKED[kind], lw=0.8, ls="--", alpha=0.7)
            if isinstance(d.units.get(base), dict):  # a unit by mode: where the mode changed
                for ts, mode in mode_changes[1:]:
                    ax.axvline(ts, color="tab:green", lw=1.0, ls=":")
                    ax.text(ts, 0.95, f" {mode}", transform=ax.get_xaxis_transform(), fontsize=7,
                            color="tab:green", va="top")  # fmt: skip
            ax.set_ylabel(f"{base} [{axis_unit(base, d)}]")
            ax.grid(True, alpha=0.3)
            if len(cols) > 1:
                ax.legend(fontsize=7, ncol=min(len(cols), 4), loc="upper right")
        top = axes[0, 0]
        for ts, kind, name in marks[:MAX_LABELS]:
            top.text(ts, 1.02, name, transform=top.get_xaxis_transform(), rotation=60, fontsize=7,
                     color=MARKED[kind], ha="left", va="bottom")  # fmt: skip
        axes[-1, 0].set_xlabel("time since the log started [s]" if d.meta else "time from the first row [s]")
        title = log.name + (f" (started {d.meta['start_utc']})" if d.meta.get("start_utc") else "")
        fig.suptitle(title, y=0.995)
        fig.tight_layout()
        fig.savefig(out, dpi=110, format=form)
        plt.close(fig)
    skipped = f", {len(marks) - MAX_LABELS} more not named" if len(marks) > MAX_LABELS else ""
    return (
        f"{out}: {len(groups)} plots, {len(d.data)} samples over {t[-1] - t[0]:.2f} s, "
        f"{len(marks)} events{skipped} ({form})"
    )
