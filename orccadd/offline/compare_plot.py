"""`orccadctl compare A B -o cmp.png`: both runs overlaid, a row per task and a column per
joint, against time since the task's start: q solid and the command dashed (where it is a
position, in rad; a torque command is another unit and is left out), A blue, B orange."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from orccadd.offline.plot import output_format
from orccadd.offline.runs import Run, TaskWindow

if TYPE_CHECKING:
    from matplotlib.axes import Axes

COLOURS = {"A": "tab:blue", "B": "tab:orange"}
PANEL_IN = (2.8, 1.9)  # a panel's width and height, inches


def task_pairs(a: Run, b: Run) -> list[tuple[TaskWindow, TaskWindow]]:
    """The task windows both runs have, paired by name and occurrence, in A's order."""
    wb = {w.key: w for w in b.windows}
    return [(w, wb[w.key]) for w in a.windows if w.key in wb]


def draw_overlay(a: Run, b: Run, out: Path) -> str:
    """Draw to `out` (PNG or SVG by its suffix); a line saying what was drawn."""
    form = output_format(out, None)
    pairs = task_pairs(a, b)
    signal = "q" if a.joint_cols("q") and b.joint_cols("q") else "cmd"
    joints = [j for j in a.joint_cols(signal) if j in b.joint_cols(signal)]
    if not pairs or not joints:
        why = "no task ran in both" if not pairs else "neither q nor cmd is in both logs"
        raise ValueError(f"{out}: nothing to draw: {why}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(
        len(pairs), len(joints), squeeze=False, sharex="row",
        figsize=(PANEL_IN[0] * len(joints), PANEL_IN[1] * len(pairs) + 0.8),
    )  # fmt: skip
    for row, (wa, wb) in enumerate(pairs):
        for col, joint in enumerate(joints):
            ax = axes[row, col]
            for name, run, w in (("A", a, wa), ("B", b, wb)):
                _lines(ax, name, run, w, signal, joint)
            if row == 0:
                ax.set_title(joint, fontsize=8)
            if col == 0:
                da, db = wa.end_s(a.end_s) - wa.start_s, wb.end_s(b.end_s) - wb.start_s
                ax.set_ylabel(f"{wa.key}\n{da:.2f} s / {db:.2f} s\n{signal} [rad]", fontsize=8)
            if row == len(pairs) - 1:
                ax.set_xlabel("since the task's start [s]", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.grid(True, alpha=0.3)
    handles = [
        Line2D([], [], color=COLOURS["A"], label=f"A {a.path.name}"),
        Line2D([], [], color=COLOURS["B"], label=f"B {b.path.name}"),
        Line2D([], [], color="gray", ls="--", label="command (position)"),
    ]
    fig.legend(handles=handles, loc="upper center", ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.5 / fig.get_figheight()))
    fig.savefig(out, dpi=90, format=form)
    plt.close(fig)
    return f"{out}: {len(pairs)} tasks x {len(joints)} joints, both runs overlaid ({form})"


def _lines(ax: Axes, name: str, run: Run, w: TaskWindow, signal: str, joint: str) -> None:
    rows = run.rows(w)
    t = run.t[rows] - w.start_s
    colour = COLOURS[name]
    y = run.log.data[rows, run.joint_cols(signal)[joint]]
    ax.plot(t, y, color=colour, lw=1.0)
    cmd = run.joint_cols("cmd").get(joint)
    if signal == "q" and cmd is not None:
        position = run.mode_at(run.t[rows]) == "position"
        c = np.where(position, run.log.data[rows, cmd], np.nan)
        ax.plot(t, c, color=colour, lw=0.8, ls="--")
