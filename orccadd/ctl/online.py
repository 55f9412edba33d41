"""orccadctl commands that talk to a running orccadd (through its command daemon)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from orccadd.ctl.client import Client, ClientError, default_socket
from orccadd.wire.commands import COMMANDS
from orccadd.wire.socketdir import urgent_socket_path

EXIT_OK, EXIT_REFUSED, EXIT_ERROR = 0, 1, 2


def add_parsers(sub: Any) -> None:
    def add(name: str, help_: str = "") -> argparse.ArgumentParser:
        """A subcommand; its help is the command table's unless given (composite commands)."""
        text = help_ or COMMANDS[name].help.replace("`", "")
        p: argparse.ArgumentParser = sub.add_parser(name, help=text, description=text)
        p.add_argument("--socket", default=None, help=f"the daemon's socket (default {default_socket()})")
        p.add_argument("--json", action="store_true", help="print the daemon's JSON reply")
        p.set_defaults(func=run_online, online=name)
        return p

    add("status")
    add("describe")
    p = add("load")
    p.add_argument("mission")
    p = add("start")
    p.add_argument("procedure", nargs="?", default="")
    add("stop")
    add("abort")
    add("hold")
    add("resume")
    add("reset")
    p = add("send")
    p.add_argument("input")
    p = add("params")
    p.add_argument("task", nargs="?", default="")
    p = add("tune")
    p.add_argument("path")
    p.add_argument("value", help="a number or a JSON list")
    p = add("monitor")
    p.add_argument("signals", nargs="*")
    p.add_argument("--rate", type=float, default=10.0, help="samples per second")
    p.add_argument("--count", type=int, default=0, help="stop after N samples")
    p.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
    p = add("events")
    p.add_argument("--last", type=int, default=50)
    p.add_argument("--follow", action="store_true")
    p.add_argument("--duration", type=float, default=0.0)
    p = add("top", "a live terminal view (state, tasks, joints, timing, last events)")
    p.add_argument("--rate", type=float, default=4.0)
    p.add_argument("--count", type=int, default=0, help="refreshes before exiting (0: until Ctrl-C)")
    p = add("log")
    p.add_argument("action", choices=COMMANDS["log"].arg("action").choices)
    p.add_argument("signals", nargs="*")
    p.add_argument("-o", "--output", default="", help="start: also copy the CSV here at `log stop`")
    p = add("inject")
    p.add_argument("fault", choices=COMMANDS["inject"].arg("fault").choices)
    p.add_argument("--ticks", type=int, default=20)
    p.add_argument("--extra-ms", type=float, default=0.0)
    p = sub.add_parser("plot", help="plot a CSV log to a PNG (no daemon needed)")
    p.add_argument("log")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--signals", default="", help="comma-separated column prefixes (default: all)")
    p.set_defaults(func=run_plot)


def _args(a: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    cmd = a.online
    if cmd == "load":
        return cmd, {"path": str(Path(a.mission).resolve())}
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
            args["signals"] = a.signals or ["q", "dq", "tau", "cmd"]
            if a.output:  # the daemon writes into its own log directory; we copy it at `log stop`
                args["name"] = Path(a.output).name
                args["dest"] = str(Path(a.output).resolve())
        return cmd, args
    if cmd == "inject":
        return cmd, {"fault": a.fault, "ticks": a.ticks, "extra_ms": a.extra_ms}
    return cmd, {}


def _urgent_reply(a: argparse.Namespace) -> dict[str, Any] | None:
    """`abort` and `stop` through the real-time process's own socket, when it is there (no
    queue of other clients' requests in front of them); None: use the main socket."""
    path = urgent_socket_path(a.socket or default_socket())
    if not os.path.exists(path):
        return None
    try:
        with Client(path) as c:
            return c.reply(a.online)
    except (ClientError, OSError):
        return None


def run_online(a: argparse.Namespace) -> int:
    r = _urgent_reply(a) if a.online in ("abort", "stop") else None
    if r is None:
        try:
            online = _online(a)
        except ClientError as e:
            print(f"error: {e}", file=sys.stderr)
            return EXIT_ERROR
        if isinstance(online, int):
            return online
        r = online
    return _report(a, r)


def _online(a: argparse.Namespace) -> dict[str, Any] | int:
    """The reply to the command of `a` through the command daemon, or an exit status for the
    streaming commands (monitor, events --follow, top)."""
    with Client(a.socket) as c:
        if a.online == "monitor":
            return _monitor(c, a)
        if a.online == "events" and a.follow:
            return _follow(c, a)
        if a.online == "top":
            return _top(c, a)
        if a.online == "events":
            return c.reply("events", last=a.last)
        cmd, args = _args(a)
        return c.reply(cmd, **args)


def _report(a: argparse.Namespace, r: dict[str, Any]) -> int:
    fetched = EXIT_OK
    if r.get("ok") and a.online == "log" and a.action == "stop" and r["result"].get("dest"):
        fetched = _fetch_log(r["result"], quiet=a.json)
    if a.json:
        print(json.dumps(r, indent=1))
        return (EXIT_OK if r.get("ok") else EXIT_REFUSED) or fetched
    if not r.get("ok"):
        print(f"refused: {r.get('error')}", file=sys.stderr)
        return EXIT_REFUSED
    if a.online != "log" or not r["result"].get("dest"):
        _print(a.online, r["result"])
    return fetched


def _fetch_log(info: dict[str, Any], quiet: bool) -> int:
    """Copy the daemon's log file to where `log start -o` asked, with this user's rights."""
    import shutil

    try:
        shutil.copyfile(info["file"], info["dest"])
    except OSError as e:
        print(
            f"log: {info['rows']} rows in {info['file']}; not copied to {info['dest']}: {e}", file=sys.stderr
        )
        return EXIT_ERROR
    if not quiet:
        print(f"log: {info['rows']} rows ({info['lost']} lost) in {info['dest']} (kept in {info['file']})")
    return EXIT_OK


def _print(cmd: str, res: Any) -> None:
    if cmd == "status":
        print(format_status(res))
    elif cmd == "events":
        from orccadd.ctl.format import format_trace

        for e in res["events"]:
            print(format_trace(e))
    elif cmd == "load":
        print(res["report"])
    elif cmd == "params":
        for task, params in res["params"].items():
            for p in params:
                flag = "" if p["tunable"] else "  (not tunable)"
                print(f"{task}.{p['name']:28s} = {p['value']}  {p['bounds']} {p['unit']}{flag}")
    else:
        print(json.dumps(res) if not isinstance(res, str) else res)


def format_status(s: dict[str, Any]) -> str:
    lines = [
        f"{s.get('robot')}: {s['state']}"
        + (f", mission {s['mission']}" if s.get("mission") else "")
        + (f" (automaton state {s['automaton_state']})" if s["automaton_state"] >= 0 else "")
        + (f", FAULTED: {s.get('fault') or '?'} (reset needed)" if s.get("faulted") else ""),
        f"active task {s.get('active_task')} ({s.get('task_phase')}), last result {s['result']}, "
        f"resource {','.join(s.get('resource_status') or ['ok'])}",
    ]
    t = s.get("timing") or {}
    if t:
        lines.append(
            f"loop: {s['ticks']} ticks, {s['overruns']} overruns, {s['switches']} switches; wake-up median "
            f"{t['wake_median_us']} p99 {t['wake_p99_us']} max {t['wake_max_us']} µs; compute median "
            f"{t['compute_median_us']} p99 {t['compute_p99_us']} µs"
        )
    lines.append(f"{'joint':22s} {'q rad':>10s} {'dq rad/s':>10s} {'tau N.m':>10s} {'cmd':>10s}")
    for j in s.get("joints", []):
        lines.append(
            f"{j['name']:22s} {j['q_rad']:10.4f} {j['dq_rad_s']:10.4f} {j['tau_nm']:10.2f} {j['cmd']:10.2f}"
        )
    if s.get("log"):
        lg = s["log"]
        lines.append(f"log: {lg['file']} ({lg['rows']} rows, {lg['lost']} lost)")
    return "\n".join(lines)


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
        pass
    except BrokenPipeError:
        _stdout_gone()
    return EXIT_OK


def _follow(c: Client, a: argparse.Namespace) -> int:
    from orccadd.ctl.format import format_trace

    args: dict[str, Any] = {"last": a.last, "follow": True}
    if a.duration:
        args["duration_s"] = a.duration
    try:
        for e in c.stream("events", **args):
            print(json.dumps(e) if a.json else format_trace(e), flush=True)
    except KeyboardInterrupt:
        pass
    except BrokenPipeError:
        _stdout_gone()
    return EXIT_OK


def _top(c: Client, a: argparse.Namespace) -> int:
    from orccadd.ctl.format import format_trace

    n = 0
    try:
        while not a.count or n < a.count:
            s = c.call("status")
            ev = c.call("events", last=8)["events"]
            screen = format_status(s) + "\n\nlast events:\n" + "\n".join(format_trace(e) for e in ev)
            if sys.stdout.isatty():
                print("\x1b[H\x1b[2J" + screen, flush=True)
            else:
                print(screen + "\n", flush=True)
            n += 1
            time.sleep(1.0 / a.rate)
    except KeyboardInterrupt:
        pass
    except BrokenPipeError:
        _stdout_gone()
    return EXIT_OK


def run_plot(a: argparse.Namespace) -> int:
    from orccadd.ctl.plot import plot_csv

    try:
        info = plot_csv(Path(a.log), Path(a.output), [s for s in a.signals.split(",") if s])
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_ERROR
    print(info)
    return EXIT_OK
