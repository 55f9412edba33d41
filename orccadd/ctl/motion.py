"""`orccadctl move`, `jog` and `follow`: ad-hoc motion, without writing a mission.

The daemon writes a one-task mission, verifies it as `load` does and starts it
(`orccadd/daemon/adhoc.py`); orccadctl then waits for the run to end (unless `--no-wait`) and
says how: arrived (exit 0), or not (the result and the stop's cause; exit 1). Ctrl-C while it
waits sends `stop`: the run ends and the arm is held where it is (exit 130).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from orccadd.cellnet.console import CellError
from orccadd.ctl.cell import RemoteClient
from orccadd.ctl.client import Client, ClientError, socket_help
from orccadd.ctl.format import error_line
from orccadd.wire.commands import COMMANDS, MAX_LINE, client_wait_s, encode
from orccadd.wire.schema import PROTOCOL_VERSION

EXIT_OK, EXIT_REFUSED, EXIT_ERROR, EXIT_INTERRUPTED = 0, 1, 2, 130
POLL_S = 0.1  # how often the end of the run is asked for
RUNNING = ("running", "holding")
Connection = Client | RemoteClient


def add_parsers(sub: Any) -> None:
    def add(name: str) -> argparse.ArgumentParser:
        text = COMMANDS[name].help.replace("`", "")
        p: argparse.ArgumentParser = sub.add_parser(name, help=text, description=text)
        p.add_argument("--socket", default=None, metavar="PATH", help=socket_help())
        p.add_argument("--json", action="store_true", help="print the daemon's JSON reply, and the run's end")
        p.add_argument("--no-wait", action="store_true", help="return once started; do not wait for the end")
        p.set_defaults(func=run_motion, online=name)
        return p

    def resource(p: argparse.ArgumentParser, cmd: str) -> None:
        p.add_argument("--resource", default="", metavar="NAME", help=COMMANDS[cmd].arg("resource").help)

    p = add("move")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument(
        "--joints",
        metavar="Q1,Q2,...",
        help="the target, one value per joint, in rad, comma-separated (`--joints=-0.5,...` works too)",
    )
    target.add_argument(
        "--pose",
        metavar="X,Y,Z[,ROLL,PITCH,YAW]",
        help="the tool's target, along a straight line: x, y, z in m (base frame), then roll, pitch, "
        "yaw in rad about the base's axes (left out: the tool keeps its orientation)",
    )
    resource(p, "move")
    p.add_argument(
        "--speed-scale", type=float, default=0.5, metavar="S", help=COMMANDS["move"].arg("speed_scale").help
    )
    p = add("jog")
    p.add_argument("--joint", required=True, metavar="NAME", help=COMMANDS["jog"].arg("joint").help)
    p.add_argument("--by", type=float, required=True, metavar="RAD", help=COMMANDS["jog"].arg("by_rad").help)
    resource(p, "jog")
    p.add_argument(
        "--speed-scale", type=float, default=0.5, metavar="S", help=COMMANDS["jog"].arg("speed_scale").help
    )
    p = add("follow")
    p.add_argument("trajectory", help="a CSV file: header t_s,<joint names>, a row per point, t_s from 0")
    resource(p, "follow")


def joined_values(argv: list[str]) -> list[str]:
    """`--joints -0.5,1` as `--joints=-0.5,1` (and `--pose`'s): argparse takes a value that starts
    with `-` and is not one number for an option."""
    out: list[str] = []
    it = iter(argv)
    for word in it:
        nxt = next(it, None) if word in ("--joints", "--pose") else None
        out.append(f"{word}={nxt}" if nxt is not None else word)
    return out


def request(a: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    """The command and its arguments; `ClientError` for what this side can tell is wrong."""
    cmd: str = a.online
    args: dict[str, Any] = {"resource": a.resource} if a.resource else {}
    if cmd == "move":
        option, text = ("--pose", a.pose) if a.pose is not None else ("--joints", a.joints)
        try:
            values = [float(x) for x in text.split(",")]
        except ValueError:
            raise ClientError(f"move: {option} {text!r}: want numbers separated by commas") from None
        key = "pose" if option == "--pose" else "joints_rad"
        return cmd, {key: values, "speed_scale": a.speed_scale, **args}
    if cmd == "jog":
        return cmd, {"joint": a.joint, "by_rad": a.by, "speed_scale": a.speed_scale, **args}
    path = Path(a.trajectory)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ClientError(f"follow: {path}: {getattr(e, 'strerror', None) or e}") from None
    args = {"csv": text, "name": path.name, **args}
    size = len(encode({"id": 1, "cmd": cmd, "args": args, "protocol": PROTOCOL_VERSION}))
    if size > MAX_LINE:
        points = max(text.count("\n") - 1, 1)
        raise ClientError(
            f"follow: {path}: {points} points make a request of {size} bytes, beyond the protocol's "
            f"{MAX_LINE}: at most about {points * MAX_LINE // size} points of these; sample it more "
            "coarsely (the daemon interpolates between the points by a cubic spline)"
        )
    return cmd, args


def run_motion(a: argparse.Namespace) -> int:
    try:
        cmd, args = request(a)
        robot = getattr(a, "robot", None)
        with RemoteClient(a, robot) if robot else Client(a.socket, timeout_s=client_wait_s(cmd)) as c:
            r = c.reply(cmd, **args)
            if not r.get("ok"):
                return _refused(a, r)
            if not a.json:
                print(started_words(cmd, r["result"]), flush=True)
            end = None if a.no_wait else wait_end(c)
    except (ClientError, CellError) as e:
        _say_error(a, str(e))
        return EXIT_ERROR
    except OSError as e:
        _say_error(a, f"orccadd: {e.strerror or e}")
        return EXIT_ERROR
    except KeyboardInterrupt:
        return _interrupted(a)
    if a.json:
        print(json.dumps({**r, "end": end} if end is not None else r, indent=1))
    elif end is not None:
        print(end_words(end))
    return EXIT_OK if end is None or end.get("result") == "success" else EXIT_REFUSED


def wait_end(c: Connection) -> dict[str, Any]:
    """The first status whose state is no longer running or holding (the run's end)."""
    while True:
        s = c.call("status")
        if s.get("state") not in RUNNING:
            return {k: s.get(k) for k in ("state", "result", "fault", "joints")}
        time.sleep(POLL_S)


def started_words(cmd: str, r: dict[str, Any]) -> str:
    task = Path(str(r.get("task_file", ""))).name
    if "pose" in r:  # move --pose: a position (m) and roll, pitch, yaw (rad)
        x, y, z, roll, pitch, yaw = (f"{v:.4g}" for v in r["pose"])
        goal = f"the tool to ({x}, {y}, {z}) m, rpy ({roll}, {pitch}, {yaw}) rad, along a straight line"
        return f"{cmd}: started on {r.get('resource')} ({task}), {goal}"
    target = ", ".join(f"{q:.4g}" for q in r.get("target_rad", []))
    what = f"{r.get('points')} points, {r.get('duration_s', 0):g} s, to" if cmd == "follow" else "to"
    return f"{cmd}: started on {r.get('resource')} ({r.get('mode')}: {task}), {what} [{target}] rad"


def end_words(end: dict[str, Any]) -> str:
    result = end.get("result")
    if result == "success":
        return "arrived (mission ended: success)"
    fault = end.get("fault") or {}
    why = f": {fault.get('event') or fault.get('kind')}: {fault.get('text')}" if fault else ""
    return f"did not arrive: the run ended {result}{why}" + (
        "; `orccadctl reset` once at rest" if fault else ""
    )


def _refused(a: argparse.Namespace, r: dict[str, Any]) -> int:
    if a.json:
        print(json.dumps(r, indent=1))
    else:
        print(error_line(str(r.get("error"))), file=sys.stderr)
    return EXIT_REFUSED


def _say_error(a: argparse.Namespace, message: str) -> None:
    if a.json:
        print(json.dumps({"ok": False, "error": message}, indent=1))
    else:
        print(error_line(message), file=sys.stderr)


def _interrupted(a: argparse.Namespace) -> int:
    """Ctrl-C while waiting: the run is stopped (the mission's `Stop`: held where it is)."""
    robot = getattr(a, "robot", None)
    try:
        with RemoteClient(a, robot) if robot else Client(a.socket, timeout_s=client_wait_s("stop")) as c:
            r = c.reply("stop")
        words = "stopped: the arm is held where it is" if r.get("ok") else f"not stopped: {r.get('error')}"
    except (ClientError, CellError, OSError) as e:
        words = f"not stopped ({e}): `orccadctl stop` or `abort`"
    print(words, file=sys.stderr)
    return EXIT_INTERRUPTED
