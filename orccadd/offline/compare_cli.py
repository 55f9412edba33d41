"""`orccadctl compare A.mcap B.mcap`: its options and its command. Exit 0: the same within the
tolerances; 1: different (the report says where); 2: an error (a file that is not a comparable
log, runs of two missions, an output that cannot be written). Light at import (argparse only):
the comparison's modules are imported when it runs."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import Any

from orccadd.ctl.format import error_line
from orccadd.offline.tolerances import HELP, Tolerances, option

EXIT_SAME, EXIT_DIFFERENT, EXIT_ERROR = 0, 1, 2
DESCRIPTION = (
    "compare two runs of one mission (their MCAP logs; no daemon): the reactive traces instant by "
    "instant, per task its duration, tracking error, command and torque differences and timing; "
    "a verdict against tolerances. Exit 0 the same, 1 different, 2 an error"
)


def add_parser(sub: Any) -> None:
    c = sub.add_parser("compare", help=DESCRIPTION.split(":")[0], description=DESCRIPTION)
    c.add_argument("run_a", metavar="A.mcap", help="a run's MCAP (`log stop -o run.csv` writes run.mcap)")
    c.add_argument("run_b", metavar="B.mcap", help="another run of the same mission")
    c.add_argument("--json", action="store_true", help="the report as one JSON object")
    c.add_argument("-o", "--output", default=None, metavar="cmp.png", help="draw both runs overlaid per task "
                   "and joint (png or svg)")  # fmt: skip
    c.add_argument("--mcap", default=None, metavar="cmp.mcap", help="write both runs into one MCAP, "
                   "channels /a/... and /b/... aligned on the mission's start, for Foxglove")  # fmt: skip
    defaults = Tolerances()
    for f in fields(Tolerances):
        d = getattr(defaults, f.name)
        c.add_argument(option(f.name), dest=f"tol_{f.name}", type=float, default=d, metavar="X",
                       help=HELP[f.name] + ("" if d is None else f" (default {d})"))  # fmt: skip
    c.set_defaults(func=cmd_compare)


def cmd_compare(a: argparse.Namespace) -> int:
    from orccadd.errors import OrccaddError
    from orccadd.offline.compare import compare_runs
    from orccadd.offline.compare_text import compare_text
    from orccadd.offline.runs import load_run

    try:
        tol = Tolerances(**{f.name: getattr(a, f"tol_{f.name}") for f in fields(Tolerances)})
        ra, rb = load_run(Path(a.run_a)), load_run(Path(a.run_b))
        rep = compare_runs(ra, rb, tol)
        out = rep.as_json()
        if a.output:
            from orccadd.offline.compare_plot import draw_overlay

            out["plot"] = _written(lambda: draw_overlay(ra, rb, Path(a.output)), a.output)
        if a.mcap:
            from orccadd.offline.compare_mcap import write_overlay

            out["mcap"] = _written(lambda: write_overlay(ra, rb, Path(a.mcap)), a.mcap)
    except OrccaddError as e:
        if a.json:
            print(json.dumps({"verdict": "error", "error": str(e)}))
        print(error_line(str(e)), file=sys.stderr)
        return EXIT_ERROR
    if a.json:
        print(json.dumps(out))
    else:
        print(compare_text(out))
        for k in ("plot", "mcap"):
            if k in out:
                print(out[k])
    return EXIT_SAME if rep.same else EXIT_DIFFERENT


def _written(write: Callable[[], str], path: str) -> str:
    """What `write()` says it wrote; an `OrccaddError` naming `path` if it could not."""
    from orccadd.errors import OrccaddError

    try:
        return write()
    except (OSError, ValueError) as e:
        raise OrccaddError(f"{path}: not written ({e})") from None
