"""`orccadctl cell status|top|events` and `orccadctl --robot NAME COMMAND`: every daemon of a cell
of robot PCs from one console, over Zenoh (`orccadd.cellnet`)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

from orccadd.cellnet import keys
from orccadd.cellnet.console import CellConsole, CellError, read_console_config
from orccadd.ctl.format import error_line, format_trace, state_words
from orccadd.errors import ConfigError
from orccadd.fault import cause_words

EXIT_OK, EXIT_REFUSED, EXIT_ERROR, EXIT_INTERRUPTED = 0, 1, 2, 130
LOST_LABEL = "LOST"


def cell_file(a: argparse.Namespace) -> str:
    path = getattr(a, "cell", None) or os.environ.get("ORCCADD_CELL", "")
    if not path:
        raise CellError(
            "no cell: give --cell FILE (a [cell] table: name, connect, TLS files) or set $ORCCADD_CELL"
        )
    return str(path)


def open_console(a: argparse.Namespace) -> CellConsole:
    return CellConsole(read_console_config(cell_file(a)))


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "cell",
        help="every daemon of a cell of robot PCs (over Zenoh): status, top, events",
        description="Every daemon of a cell from one console: `status` (one table), `top` (live), "
        "`events` (merged, time-ordered). A command to one daemon: orccadctl --robot NAME COMMAND.",
    )
    p.add_argument("view", choices=("status", "top", "events"), help="what to show")
    p.add_argument("--cell", default=None, metavar="FILE", help="the console's [cell] table ($ORCCADD_CELL)")
    p.add_argument("--json", action="store_true", help="JSON lines")
    p.add_argument("--follow", action="store_true", help="events: keep following")
    p.add_argument(
        "--duration", type=float, default=0.0, metavar="S", help="top, events --follow: stop after S s"
    )
    p.add_argument("--rate", type=float, default=2.0, metavar="HZ", help="top: refreshes per second")
    p.add_argument("--count", type=int, default=0, help="top: refreshes before exiting (0: until Ctrl-C)")
    p.add_argument("--last", type=int, default=20, metavar="N", help="events: each daemon's last N first")
    p.set_defaults(func=run_cell, online="cell")


def run_cell(a: argparse.Namespace) -> int:
    try:
        with open_console(a) as console:
            if a.view == "status":
                return _status(console, a)
            if a.view == "top":
                return _top(console, a)
            return _events(console, a)
    except (CellError, ConfigError) as e:
        _error(a, str(e))
        return EXIT_ERROR
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


def _error(a: argparse.Namespace, message: str) -> None:
    if getattr(a, "json", False):
        print(json.dumps({"ok": False, "error": message}))
    else:
        print(error_line(message), file=sys.stderr)


def _status(console: CellConsole, a: argparse.Namespace) -> int:
    replies = console.status_all()
    if not replies and not console.reaches_anyone():
        _error(a, f"cell {console.net.name}: {console.why_alone()}")
        return EXIT_REFUSED
    absent = set(console.net.daemons) - set(replies)  # the console's daemons not online
    if a.json:
        print(json.dumps({"cell": console.net.name, "robots": replies, "lost": sorted(absent)}, indent=1))
    else:
        print(status_table(console.net.name, replies, absent))
    return EXIT_OK if replies else EXIT_REFUSED


def status_table(cell: str, replies: dict[str, dict[str, Any]], lost: set[str] | None = None) -> str:
    """One line per daemon: state, mission, result, fault, wake-up p99, overruns."""
    head = (
        f"{'robot':<16} {'state':<10} {'mission':<22} {'result':<10} {'wake p99':>9} {'overruns':>8}  fault"
    )
    lines = [f"cell {cell}: {len(replies)} daemon(s)", head]
    for robot, r in sorted(replies.items()):
        if not r.get("ok"):
            lines.append(f"{robot:<16} {'?':<10} {str(r.get('error'))[:70]}")
            continue
        st = r["result"]
        p99 = (st.get("timing") or {}).get("wake_p99_us")
        wake = f"{p99:.0f} µs" if isinstance(p99, int | float) else "-"
        faults = [st] + [x for x in st.get("resources") or [] if x.get("fault")]
        fault = "; ".join(
            (f"{x['name']}: " if x is not st else "") + cause_words(x.get("fault"))
            for x in faults
            if x.get("fault") or (x is st and st.get("faulted"))
        )
        fault += " (`reset` needed)" if fault else ""
        lines.append(
            f"{robot:<16} {state_words(st):<10} {st.get('mission') or '-'!s:<22} "
            f"{st.get('result', '?'):<10} {wake:>9} {st.get('overruns', 0):>8}  {fault}"
        )
    for robot in sorted(lost or ()):
        lines.append(f"{robot:<16} {LOST_LABEL:<10} (not online: its liveliness token is gone or never came)")
    return "\n".join(lines)


class RemoteClient:
    """`ctl.client.Client`'s interface to one daemon of the cell (`orccadctl --robot NAME …`)."""

    def __init__(self, a: argparse.Namespace, robot: str) -> None:
        self.console = open_console(a)
        self.robot = robot
        self.next_id = 0

    def __enter__(self) -> RemoteClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.console.close()

    def reply(self, cmd: str, **args: Any) -> dict[str, Any]:
        r = self.console.request(self.robot, cmd, **args)
        self.next_id = self.console.next_id
        return r

    def call(self, cmd: str, **args: Any) -> Any:
        r = self.reply(cmd, **args)
        if not r.get("ok"):
            raise CellError(str(r.get("error")))
        return r["result"]


def _top(console: CellConsole, a: argparse.Namespace) -> int:
    """The status table refreshed; a daemon whose token goes shows as LOST until it is back."""
    if a.rate <= 0:
        raise CellError(f"cell top: --rate (={a.rate:g}) must be positive")
    seen: set[str] = set(console.net.daemons)  # a daemon of the console's never seen is lost too
    n = 0
    t_end = time.monotonic() + a.duration if a.duration else float("inf")
    while (not a.count or n < a.count) and time.monotonic() < t_end:
        replies = console.status_all()
        seen |= set(replies)
        lost = seen - set(replies)
        if a.json:
            print(json.dumps({"t": time.time(), "robots": replies, "lost": sorted(lost)}), flush=True)
        else:
            if sys.stdout.isatty():
                print("\x1b[H\x1b[2J", end="")
            print(status_table(console.net.name, replies, lost), flush=True)
        n += 1
        time.sleep(1.0 / a.rate)
    return EXIT_OK


def _events(console: CellConsole, a: argparse.Namespace) -> int:
    """Each daemon's last events, merged by time; with --follow, every new one as it comes and
    each daemon joining or lost."""
    backlog: list[tuple[float, str, dict[str, Any]]] = []
    for robot in console.robots():
        r = console.request(robot, "events", last=a.last)
        for e in r.get("result", {}).get("events", []) if r.get("ok") else []:
            backlog.append((float(e.get("wall_s", 0.0)), robot, e))
    for _, robot, e in sorted(backlog, key=lambda x: x[0]):
        _print_event(a, robot, e)
    if not a.follow:
        return EXIT_OK
    t_end = time.monotonic() + a.duration if a.duration else float("inf")
    for robot, msg in console.follow(keys.EVENTS):
        if time.monotonic() >= t_end:
            break
        if msg is not None:
            _print_event(a, robot, msg)
    return EXIT_OK


def _print_event(a: argparse.Namespace, robot: str, e: dict[str, Any]) -> None:
    if a.json:
        print(json.dumps({"robot": robot, **e}), flush=True)
    elif "cell" in e:
        print(f"[{robot}] {e['cell']} ({time.strftime('%H:%M:%S')})", flush=True)
    else:
        print(f"[{robot}] {format_trace(e)}", flush=True)
