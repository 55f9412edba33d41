"""`orccadctl replay RUN.mcap`: its options, its command and its report in words. Exit 0: the
commands are identical (within `--tol`, exact by default); 1: they diverge (the report names the
first tick, task and signal, and by how much); 2: an error (a log that cannot be replayed, a
task or parameter the mission does not have). Light at import (argparse only)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from orccadd.ctl.format import error_line

EXIT_IDENTICAL, EXIT_DIVERGED, EXIT_ERROR = 0, 1, 2
DESCRIPTION = (
    "replay a logged run's measurements through its tasks' modules (offline, no daemon) and compare "
    "the commands with the ones the run sent: identical, or the first tick, task and signal where "
    "they diverge. Exit 0 identical, 1 diverged, 2 an error"
)


def add_parser(sub: Any) -> None:
    p = sub.add_parser("replay", help=DESCRIPTION.split(" (")[0], description=DESCRIPTION)
    p.add_argument("run", metavar="RUN.mcap", help="a run's MCAP, logged by a plain `log start`")
    p.add_argument("--task", default="", help="replay this task's windows only (default: every mission task)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="TASK.MODULE.PARAM=VALUE",
                   help="a parameter changed for the replay (repeatable)")  # fmt: skip
    p.add_argument("--config", default=None, help="the robot config (default: the one the run record names)")
    p.add_argument("--mission", default=None, help="replay these mission and task files instead of the "
                   "ones the log carries (a changed module or task file)")  # fmt: skip
    p.add_argument("--tol", type=float, default=0.0, metavar="X",
                   help="the command difference taken as identical (default 0: bit for bit)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="the report as one JSON object")
    p.set_defaults(func=cmd_replay)


def cmd_replay(a: argparse.Namespace) -> int:
    from orccadd.errors import OrccaddError
    from orccadd.offline.replay import parse_sets, replay, report_dict
    from orccadd.offline.replayrun import read_run

    try:
        if not a.tol >= 0:
            raise OrccaddError(f"--tol {a.tol}: a difference, 0 or more")
        run = read_run(Path(a.run))
        rep = replay(
            run,
            Path(a.config) if a.config else None,
            Path(a.mission) if a.mission else None,
            a.task,
            parse_sets(a.sets),
            a.tol,
        )
    except OrccaddError as e:
        if a.json:
            print(json.dumps({"identical": None, "error": str(e)}))
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_ERROR
    out = report_dict(rep)
    print(json.dumps(out) if a.json else replay_text(out))
    return EXIT_IDENTICAL if rep.identical else EXIT_DIVERGED


def replay_text(r: dict[str, Any]) -> str:
    exact = "bit for bit" if not r["tolerance"] else f"within {r['tolerance']:g}"
    lines = [f"replay of {r['run']}: mission {r['mission']}, robot config {r['config']}"]
    width = max(len(t["task"]) for t in r["tasks"])
    for t in r["tasks"]:
        head = f"  {t['task']:<{width}}  ticks {t['first_tick']}-{t['first_tick'] + t['ticks'] - 1}"
        d = t["divergence"]
        if d is None:
            lines.append(f"{head}: identical ({exact})")
        else:
            lines.append(
                f"{head}: diverges at tick {d['tick']} ({d['time_s']:.3f} s into the task): {d['signal']} "
                f"{d['run']:.9g} in the run, {d['replay']:.9g} replayed (by {d['by']:.3g}); "
                f"{t['differing_ticks']} ticks differ, by at most {t['max_diff']:.3g}"
            )
        lines.extend(f"    {n}" for n in t["notes"])
    lines.extend(f"  note: {n}" for n in r["notes"])
    ticks = sum(t["ticks"] for t in r["tasks"])
    speed = f"{r['run_s'] / r['elapsed_s']:.1f}x real time" if r["elapsed_s"] > 0 else "-"
    if r["identical"]:
        verdict = f"identical: {ticks} ticks of {len(r['tasks'])} task runs, the same commands ({exact})"
    else:
        first = min((t for t in r["tasks"] if t["divergence"]), key=lambda t: t["divergence"]["tick"])
        d = first["divergence"]
        verdict = f"diverged: first at tick {d['tick']}, task {first['task']}, {d['signal']} by {d['by']:.3g}"
    lines.append(f"verdict: {verdict} (replayed in {r['elapsed_s']:.2f} s, {speed})")
    return "\n".join(lines)
