"""orccadctl commands that talk to a running orccadd (through its command daemon)."""

from __future__ import annotations

import argparse
import errno
import json
import os
import stat
import sys
import time
from pathlib import Path
from typing import Any

from orccadd.cellnet.console import CellError
from orccadd.ctl.cell import RemoteClient
from orccadd.ctl.client import Client, ClientError, default_socket, socket_help
from orccadd.ctl.format import error_line, format_trace
from orccadd.ctl.format import format_status as format_status  # the demo prints it
from orccadd.ctl.human import context_requests, format_reply
from orccadd.errors import ConfigError
from orccadd.wire.commands import COMMANDS, LOG_SIGNALS, URGENT_COMMANDS, client_wait_s
from orccadd.wire.socketdir import urgent_socket_path

EXIT_OK, EXIT_REFUSED, EXIT_ERROR, EXIT_INTERRUPTED = 0, 1, 2, 130
SIGNALS_HELP = (
    "q, dq, tau, cmd (all joints), q.3 or q.elbow_joint (one), wake_us, compute_us, status, ...; "
    "in a station, each resource's, or one's: left/q"
)


def table_help(cmd: str, arg: str) -> str:
    """An argument's help as the command table declares it (one text for the CLI and the docs)."""
    return COMMANDS[cmd].arg(arg).help


def add_parsers(sub: Any) -> None:
    def add(name: str, help_: str = "") -> argparse.ArgumentParser:
        """A subcommand; its help is the command table's unless given (composite commands)."""
        text = help_ or COMMANDS[name].help.replace("`", "")
        p: argparse.ArgumentParser = sub.add_parser(name, help=text, description=text)
        p.add_argument("--socket", default=None, metavar="PATH", help=socket_help())
        p.add_argument("--json", action="store_true", help="print the daemon's JSON reply")
        p.set_defaults(func=run_online, online=name)
        return p

    add("status")
    add("describe")
    p = add("load")
    p.add_argument("mission", help="a mission file, or a shipped mission's name (demo, pick_place, ...)")
    p = add("start")
    p.add_argument("procedure", nargs="?", default="", help=table_help("start", "procedure"))
    p.add_argument(
        "--wait",
        action="store_true",
        help="wait for the run's end and say how it ended: exit 0 on success, 1 otherwise (for scripts)",
    )
    add("stop")
    add("abort")
    add("hold")
    add("resume")
    p = add("reset")
    p.add_argument("resource", nargs="?", default="", help=table_help("reset", "resource"))
    p = add("send")
    p.add_argument("input", help="an operator input the mission declares (`input` in the mission)")
    p = add("params")
    p.add_argument("task", nargs="?", default="", help=table_help("params", "task"))
    p = add("tune")
    p.add_argument("path", help="TASK.MODULE.PARAM, or TASK.MODULE.PARAM[i] for one joint's (i from 0)")
    p.add_argument("value", help="a number, or a JSON list with one per joint for a vector")
    p = add("monitor")
    p.add_argument("signals", nargs="*", help=SIGNALS_HELP)
    p.add_argument("--rate", type=float, default=10.0, help="samples per second")
    p.add_argument("--count", type=int, default=0, help="stop after N samples")
    p.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    p = add("events")
    p.add_argument("--last", type=int, default=50, metavar="N", help=table_help("events", "last"))
    p.add_argument("--follow", action="store_true", help=table_help("events", "follow"))
    p.add_argument(
        "--duration", type=float, default=0.0, metavar="S", help=table_help("events", "duration_s")
    )
    p = add(
        "top",
        "a live terminal view (state, goal, last error, joints, timing, last events); keys: "
        "q quit, p pause the display, h hold, r resume",
    )
    p.add_argument("--rate", type=float, default=4.0, metavar="HZ", help="refreshes per second")
    p.add_argument("--count", type=int, default=0, help="refreshes before exiting (0: until Ctrl-C)")
    p = add("log")
    p.add_argument("action", choices=COMMANDS["log"].arg("action").choices, help=table_help("log", "action"))
    default = " ".join(LOG_SIGNALS) + " and the resource's own signals (a wrench)"
    p.add_argument("signals", nargs="*", help="start: " + SIGNALS_HELP + f" (default: {default})")
    p.add_argument("--name", default="", help="start: the log's file name in the daemon's log directory")
    p.add_argument(
        "-o",
        "--output",
        default="",
        help="stop: copy the CSV (and its MCAP beside it) here, with your rights; a link there is refused",
    )
    p = add("inject")
    p.add_argument(
        "fault", choices=COMMANDS["inject"].arg("fault").choices, help=table_help("inject", "fault")
    )
    p.add_argument("--ticks", type=int, default=20, help=table_help("inject", "ticks"))
    p.add_argument("--extra-ms", type=float, default=0.0, metavar="MS", help=table_help("inject", "extra_ms"))
    p.add_argument("--resource", default="", help=table_help("inject", "resource"))
    from orccadd.ctl.foxglove import add_parser as add_foxglove

    add_foxglove(sub)


def _args(a: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    cmd = a.online
    if cmd == "load" and getattr(a, "robot", None):  # a name, or a path on that daemon's PC
        return cmd, {"path": a.mission}
    if cmd == "load":  # a bare name (`demo`) the daemon finds in its mission directories
        bare = "/" not in a.mission and "." not in a.mission and not Path(a.mission).exists()
        return cmd, {"path": a.mission if bare else str(Path(a.mission).resolve())}
    if cmd == "start":
        return cmd, {"procedure": a.procedure} if a.procedure else {}
    if cmd == "send":
        return cmd, {"input": a.input}
    if cmd == "params":
        return cmd, {"task": a.task} if a.task else {}
    if cmd == "tune":
        try:
            value = json.loads(a.value)
        except ValueError:
            raise ClientError(f"tune: value {a.value!r} is not a number or a JSON list") from None
        return cmd, {"path": a.path, "value": value}
    if cmd == "log":
        args: dict[str, Any] = {"action": a.action}
        if a.action == "start":
            if a.output:
                raise ClientError(
                    "log start: -o is for `log stop -o FILE` (the copy is made there, with the rights "
                    "of whoever stops the log); name the daemon's file with --name"
                )
            if a.signals:  # else the daemon's default: LOG_SIGNALS and the resource's own signals
                args["signals"] = a.signals
            if a.name:  # the daemon writes into its own log directory; `log stop -o` copies it
                args["name"] = a.name
        elif a.output and getattr(a, "robot", None):
            raise ClientError(
                f"log stop -o with --robot: the log is on {a.robot}'s PC, and its paths there mean "
                "nothing here (nothing is copied from a path another PC names); stop it without -o: "
                "it stays in that daemon's log directory"
            )
        elif a.name:
            raise ClientError("log stop: --name is for `log start`")
        elif a.signals:
            raise ClientError(f"log stop: takes no signals (got {' '.join(a.signals)[:80]})")
        return cmd, args
    if cmd == "inject":
        args = {"fault": a.fault, "ticks": a.ticks, "extra_ms": a.extra_ms}
        return cmd, {**args, "resource": a.resource} if a.resource else args
    if cmd == "reset":
        return cmd, {"resource": a.resource} if a.resource else {}
    if cmd == "events":
        return cmd, {"last": a.last}
    return cmd, {}


def _urgent_reply(a: argparse.Namespace) -> dict[str, Any] | None:
    """`abort` and `stop` through the real-time process's own socket, when it is there (no
    queue of other clients' requests in front of them); None: use the main socket. A refusal of
    the connection itself (no place free, the peer's role) is not the command's answer: it comes
    back without our request's id, and the main socket, which keeps a place for these two, is
    tried next."""
    path = urgent_socket_path(a.socket or default_socket())
    if not os.path.exists(path):
        return None
    try:
        with Client(path, timeout_s=client_wait_s(a.online)) as c:
            r = c.reply(a.online)
            return r if r.get("id") == c.next_id else None
    except (ClientError, OSError, ValueError):
        return None


def run_online(a: argparse.Namespace) -> int:
    """One command: its reply in words (or JSON); a refusal or an unreachable daemon in one
    line on stderr (the daemon's own words), Ctrl-C quietly."""
    try:
        cmd, args = _args(a)
        remote = getattr(a, "robot", None)
        r = _urgent_reply(a) if a.online in URGENT_COMMANDS and not remote else None
        context: dict[str, Any] = {}
        if r is None:
            online = _online(a, cmd, args)
            if isinstance(online, int):
                return online
            r, context = online
        code = _report(a, r, context, args)
        if a.online == "start" and getattr(a, "wait", False) and code == EXIT_OK and r.get("ok"):
            return _wait_end(a)
        return code
    except (ClientError, CellError, ConfigError) as e:
        _error(a, str(e))
    except BrokenPipeError:
        _stdout_gone()
        return EXIT_OK
    except OSError as e:  # no reply in time, the connection reset mid-reply
        _error(a, f"orccadd at {a.socket or default_socket()}: {e.strerror or e}")
    except ValueError as e:  # a reply that is not JSON
        _error(a, f"unreadable reply from orccadd: {e}")
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    return EXIT_ERROR


def _wait_end(a: argparse.Namespace) -> int:
    """`start --wait`: the run's end, in words (or JSON): 0 on success, 1 otherwise. Ctrl-C
    stops the waiting, not the run (`orccadctl stop` does that)."""
    from orccadd.ctl.motion import wait_end

    robot = getattr(a, "robot", None)
    with RemoteClient(a, robot) if robot else Client(a.socket, timeout_s=client_wait_s("status")) as c:
        end = wait_end(c)
    fault = end.get("fault") or {}
    why = f": {fault.get('event') or fault.get('kind')}: {fault.get('text')}" if fault else ""
    print(json.dumps({"end": end}, indent=1) if a.json else f"the run ended: {end.get('result')}{why}")
    return EXIT_OK if end.get("result") == "success" else 1


def _error(a: argparse.Namespace, message: str) -> None:
    """An error of the client itself (no daemon, no reply): in words on stderr, or with `--json`
    as the daemon's error replies are (`{"ok": false, "error": …}`) on stdout."""
    if getattr(a, "json", False):
        print(json.dumps({"ok": False, "error": message}, indent=1))
    else:
        print(error_line(message), file=sys.stderr)


def _online(
    a: argparse.Namespace, cmd: str, args: dict[str, Any]
) -> tuple[dict[str, Any], dict[str, Any]] | int:
    """The reply to `cmd` through the command daemon and, for words, the replies that give it
    context (`human.context_requests`); or an exit status for the streaming commands (monitor,
    events --follow, top)."""
    robot = getattr(a, "robot", None)
    if (robot and cmd in ("monitor", "top")) or (robot and cmd == "events" and a.follow):
        raise ClientError(
            f"{cmd} --robot: streams come from the cell itself: orccadctl cell top, cell events --follow"
        )
    if robot:
        with RemoteClient(a, robot) as remote:
            return _ask(remote, a, cmd, args)
    with Client(a.socket, timeout_s=client_wait_s(cmd)) as c:
        if cmd == "monitor":
            return _monitor(c, a)
        if cmd == "events" and a.follow:
            return _follow(c, a)
        if cmd == "top":
            return _top(c, a)
        return _ask(c, a, cmd, args)


def _ask(
    c: Client | RemoteClient, a: argparse.Namespace, cmd: str, args: dict[str, Any]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The reply to `cmd` and, for words, the replies that give it context."""
    r = c.reply(cmd, **args)
    context: dict[str, Any] = {}
    if r.get("ok") and not a.json:
        for name, (extra, extra_args) in context_requests(cmd, args).items():
            more = c.reply(extra, **extra_args)
            if more.get("ok"):
                context[name] = more["result"]
    return r, context


def _report(a: argparse.Namespace, r: dict[str, Any], context: dict[str, Any], args: dict[str, Any]) -> int:
    fetched = EXIT_OK
    copied = a.online == "log" and a.action == "stop" and r.get("ok") and bool(a.output)
    if copied:
        fetched = _fetch_log(r["result"], Path(a.output), quiet=a.json)
    if a.json:
        print(json.dumps(r, indent=1))
        return (EXIT_OK if r.get("ok") else EXIT_REFUSED) or fetched
    if not r.get("ok"):
        print(error_line(str(r.get("error"))), file=sys.stderr)
        return EXIT_REFUSED
    if not copied:  # a copied log is reported by _fetch_log
        print(format_reply(a.online, r["result"], context, args))
    return fetched


def _fetch_log(info: dict[str, Any], dest: Path, quiet: bool) -> int:
    """Copy the daemon's log (the CSV, and its MCAP parts beside it: run.mcap, run-2.mcap, ...)
    to `dest`, a path from this command's own line (never one the daemon stored or echoed), with
    this user's rights, through no link at its end (`copy_to`)."""
    stem = Path(info.get("name") or info["file"]).stem  # the name the log was given
    copies = []
    for csv in info.get("files") or [info["file"]]:  # a station's run.left.csv → DEST.left.csv
        suffix = Path(csv).stem.removeprefix(stem)
        copies.append((Path(csv), dest.with_name(f"{dest.stem}{suffix}.csv") if suffix else dest))
    for part in info.get("mcap", []):  # run.mcap → DEST's name with .mcap (run-2.mcap → DEST-2.mcap)
        suffix = Path(part).stem.removeprefix(stem)
        copies.append((Path(part), dest.with_name(f"{dest.stem}{suffix}.mcap")))
    for src, to in copies:
        try:
            copy_to(src, to)
        except OSError as e:
            why = f"log: {info['rows']} rows in {info['file']}; {src.name} not copied to {to}: "
            why += str(e.strerror or e)
            print(error_line(why), file=sys.stderr)
            return EXIT_ERROR
    if not quiet:
        kept = ", ".join(info.get("files") or [info["file"]])
        copied = ", ".join(str(to) for _, to in copies)
        print(f"log: {info['rows']} rows ({info['lost']} lost) in {copied} (kept in {kept})")
    return EXIT_OK


def copy_to(src: Path, dest: Path) -> None:
    """Copy `src` to `dest` with this user's rights: `src` opened without following a link at its
    end and only if it is a regular file; `dest` likewise (O_NOFOLLOW: a link planted there is
    refused, ELOOP; a FIFO or a device is refused without blocking), created with `src`'s
    permission bits at most (0644 less the umask: a 0600 log stays 0600), truncated if it is an
    existing file of ours."""
    nofollow = os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY
    fin = os.open(src, os.O_RDONLY | nofollow)
    try:
        st = os.fstat(fin)
        if not stat.S_ISREG(st.st_mode):
            raise OSError(errno.EINVAL, f"{src} is not a regular file")
        os.set_blocking(fin, True)
        fd = os.open(dest, os.O_WRONLY | os.O_CREAT | nofollow, 0o644 & stat.S_IMODE(st.st_mode))
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise OSError(errno.EINVAL, "not a regular file")
            os.set_blocking(fd, True)
            os.ftruncate(fd, 0)
            while chunk := os.read(fin, 1 << 20):
                view = memoryview(chunk)
                while view:
                    view = view[os.write(fd, view) :]
        finally:
            os.close(fd)
    finally:
        os.close(fin)


def _stdout_gone() -> None:
    """The reader of our output has gone (`| head`): end quietly, and let the interpreter's
    final flush write nowhere instead of raising again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


def _monitor(c: Client, a: argparse.Namespace) -> int:
    args: dict[str, Any] = {"signals": a.signals, "rate_hz": a.rate}
    if a.count:
        args["count"] = a.count
    if a.duration:
        args["duration_s"] = a.duration
    try:
        for item in c.stream("monitor", **args):
            if a.json:
                print(json.dumps(item), flush=True)
            elif "signals" in item:
                print(" ".join(f"{n:>14s}" for n in item["signals"]), flush=True)
            else:
                print(" ".join(f"{v:14.5f}" for v in [item["t_s"], *item["values"]]), flush=True)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _stdout_gone()
    return EXIT_OK


def _follow(c: Client, a: argparse.Namespace) -> int:
    args: dict[str, Any] = {"last": a.last, "follow": True}
    if a.duration:
        args["duration_s"] = a.duration
    try:
        for e in c.stream("events", **args):
            print(json.dumps(e) if a.json else format_trace(e), flush=True)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _stdout_gone()
    return EXIT_OK


def _top(c: Client, a: argparse.Namespace) -> int:
    """The live view on a terminal (keys: q p h r), frames one after the other elsewhere, or a
    JSON line of status and last events per refresh with --json."""
    from orccadd.ctl.terminal import AnsiScreen, TerminalKeys
    from orccadd.ctl.top import Top

    if a.rate <= 0:
        raise ClientError(f"top: --rate (={a.rate:g}) must be positive")
    try:
        if a.json:
            n = 0
            while not a.count or n < a.count:
                time.sleep(1.0 / a.rate if n else 0.0)
                frame = {"status": c.call("status"), "events": c.call("events", last=8)["events"]}
                print(json.dumps(frame), flush=True)
                n += 1
            return EXIT_OK
        with TerminalKeys() as keys, AnsiScreen() as screen:
            Top(c, keys, screen, rate_hz=a.rate, count=a.count).run()
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _stdout_gone()
    return EXIT_OK
