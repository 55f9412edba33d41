"""`orccadctl plot LOG -o out.png`: one subplot per signal group of a CSV log (matplotlib)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


def plot_csv(log: Path, out: Path, prefixes: list[str]) -> str:
    with log.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2 or not rows[0] or rows[0][0] != "time_s":
        raise ValueError(f"{log}: not an orccadd log (a CSV whose first column is time_s, with data rows)")
    header = rows[0]
    try:
        data = np.array([[float(v) for v in r] for r in rows[1:]])
    except ValueError as e:
        raise ValueError(f"{log}: {e}") from None
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(header[1:], start=1):
        base = name.split(".", 1)[0]
        if prefixes and base not in prefixes:
            continue
        groups.setdefault(base, []).append(i)
    if not groups:
        raise ValueError(f"{log}: no column matches {prefixes} (columns: {', '.join(header[1:])})")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = data[:, 0] - data[0, 0]
    fig, axes = plt.subplots(len(groups), 1, sharex=True, figsize=(10, 2.6 * len(groups)), squeeze=False)
    for ax, (base, cols) in zip(axes[:, 0], groups.items(), strict=True):
        for c in cols:
            ax.plot(t, data[:, c], lw=1.0, label=header[c].split(".", 1)[-1])
        ax.set_ylabel(base)
        ax.grid(True, alpha=0.3)
        if len(cols) > 1:
            ax.legend(fontsize=7, ncol=min(len(cols), 4), loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(log.name)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return f"{out}: {len(groups)} plots, {len(data)} samples over {t[-1]:.2f} s"
