"""`orccadctl plot LOG -o out.png|out.svg`: one panel per signal group of a log (q, dq, tau, cmd,
...), each axis with its unit, the mission's events (automaton instants, task events, operator
commands, safe stops) as vertical marks named in a lane of their own above the panels, in as
many rows as they need not to overlap (matplotlib); legends beside the panels, not over the data.

A log is its CSV or its MCAP (the same content), read by `orccadd.offline.logread`: a log
copied elsewhere plots the same. A CSV written before logs had a header plots without units or
events. A station's log: each resource's CSV, or the one MCAP of all (a panel per resource and
signal: `left/q`, `right/q`, each resource's samples at its own rate).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from orccadd.offline.logread import CsvLogData, resolve_log
from orccadd.offline.logread import log_parts as log_parts  # re-exported: plot's readers before logread
from orccadd.offline.logread import read_log as read_log
from orccadd.offline.logread import read_mcap as read_mcap

FORMATS = ("png", "svg")
MARKED = {"instant": "tab:blue", "event": "tab:red", "command": "tab:gray", "fault": "darkred"}
LANE_ROWS = 6  # rows of event names above the panels; a name that fits in none is counted, not drawn
LABEL_FONT_PT = 7


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
        # `q` names every resource's q in a station's log (`left/q`, `right/q`); `left/q` one's
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
            for c in cols:  # a column's own samples (a station's MCAP: resources at their own rates)
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
    source = f" from {log} (a station's log: every resource in its MCAP)" if log != asked else ""
    return (
        f"{out}: {len(groups)} plots, {len(d.data)} samples over {t[-1] - t[0]:.2f} s, "
        f"{len(marks)} events{skipped} ({form}){source}"
    )
