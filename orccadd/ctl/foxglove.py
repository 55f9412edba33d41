"""`orccadctl foxglove [--port N]`: a live view of a running orccadd in Foxglove.

Follows the daemon's `monitor` stream (q, dq, tau, cmd at `--rate`) and its reactive trace
(`events --follow`), and serves them with foxglove-sdk's WebSocket server bound to 127.0.0.1 only:
the robot's state is not served to the network (from another machine, tunnel the port over SSH).
Channels as in a log's MCAP: `/q`, `/dq`, `/tau`, `/cmd` (units in their schemas),
`/joint_states` (foxglove.JointStates, for a URDF layer of the 3D panel) and `/events`
(foxglove.Log). Needs the `foxglove` extra (`pip install 'orccadd[foxglove]'`).
"""

from __future__ import annotations

import argparse
import socket
import sys
import threading
import time
from typing import Any

from orccadd.ctl.client import Client, ClientError, default_socket
from orccadd.ctl.format import error_line

HOST = "127.0.0.1"  # never another address
SIGNALS = ["q", "dq", "tau", "cmd"]
UNITS = {"q": "rad", "dq": "rad/s", "tau": "N.m", "cmd": "rad, rad/s or N.m (the command mode's)"}
EXIT_OK, EXIT_ERROR, EXIT_INTERRUPTED = 0, 2, 130
STOP_WAIT_S = 2.0


def add_parser(sub: Any) -> None:
    """The `foxglove` subcommand (for orccadctl's parser)."""
    text = "serve the live state and events to Foxglove over a WebSocket on 127.0.0.1"
    p = sub.add_parser("foxglove", help=text, description=text)
    p.add_argument("--socket", default=None, help=f"the daemon's socket (default {default_socket()})")
    p.add_argument("--port", type=int, default=8765, help="the WebSocket's port on 127.0.0.1 (0: any free)")
    p.add_argument("--rate", type=float, default=50.0, help="samples per second")
    p.set_defaults(func=run_foxglove)


class LiveView:
    """The WebSocket server and its channels, in a context of their own."""

    def __init__(self, labels: list[str], port: int) -> None:
        import foxglove
        from foxglove.channels import JointStatesChannel, LogChannel

        self.ctx = foxglove.Context()
        self.lock = threading.Lock()
        self.stopped = False
        self.groups: dict[str, tuple[foxglove.Channel, list[tuple[str, int]]]] = {}
        for i, label in enumerate(labels):
            base, _, joint = label.partition(".")
            if base not in self.groups:
                unit = UNITS.get(base, "1")
                schema = {"title": f"orccadd.{base}", "description": f"{base} [{unit}]", "type": "object"}
                ch = foxglove.Channel(f"/{base}", schema=schema, context=self.ctx, metadata={"unit": unit})
                self.groups[base] = (ch, [])
            self.groups[base][1].append((joint or "value", i))
        self.joint_states = JointStatesChannel("/joint_states", context=self.ctx)
        self.events = LogChannel("/events", context=self.ctx)
        self.index = {label: i for i, label in enumerate(labels)}
        self.joints = [label.partition(".")[2] for label in labels if label.startswith("q.")]
        self.server = foxglove.start_server(name="orccadd", host=HOST, port=port, context=self.ctx)

    @property
    def port(self) -> int:
        return int(self.server.port)

    def sample(self, t_s: float, values: list[float]) -> None:
        """One monitor sample: every group's channel and the joint states."""
        from foxglove.messages import JointState, JointStates, Timestamp

        ns = time.time_ns()
        with self.lock:
            if self.stopped:
                return
            for ch, fields in self.groups.values():
                ch.log({"t_s": t_s, **{f: values[i] for f, i in fields}}, log_time=ns)

            def val(label: str) -> float | None:
                i = self.index.get(label)
                return values[i] if i is not None else None

            joints = [
                JointState(name=j, position=val(f"q.{j}"), velocity=val(f"dq.{j}"), effort=val(f"tau.{j}"))
                for j in self.joints
            ]
            stamp = Timestamp(sec=ns // 10**9, nsec=ns % 10**9)
            self.joint_states.log(JointStates(timestamp=stamp, joints=joints), log_time=ns)

    def event(self, e: dict[str, Any]) -> None:
        """One trace record as `events` decodes it."""
        from foxglove.messages import Log, LogLevel, Timestamp

        ns = time.time_ns()
        if e.get("kind") == "instant":
            text = f"{'+'.join(e.get('inputs', []))} -> {' '.join(e.get('actions', []))}"
        else:
            text = str(e.get("event", e.get("command", "?")))
        level = LogLevel.Error if ".T3." in text else LogLevel.Warning if ".T2." in text else LogLevel.Info
        stamp = Timestamp(sec=ns // 10**9, nsec=ns % 10**9)
        seq = max(int(e.get("seq", 0)), 0)
        msg = Log(timestamp=stamp, level=level, message=text, name=f"orccadd.{e.get('kind', '?')}", line=seq)
        with self.lock:
            if not self.stopped:
                self.events.log(msg, log_time=ns)

    def stop(self) -> None:
        """Stop serving; returns once the port is closed (the SDK closes it in the background)."""
        with self.lock:
            if self.stopped:
                return
            self.stopped = True
            port = self.port
            self.server.stop()
        end = time.monotonic() + STOP_WAIT_S
        while time.monotonic() < end:
            with socket.socket() as s:
                if s.connect_ex((HOST, port)) != 0:
                    return
            time.sleep(0.01)


def _follow_events(socket: str | None, view: LiveView) -> None:
    try:
        with Client(socket) as c:
            for e in c.stream("events", last=0, follow=True):
                view.event(e)
    except (ClientError, OSError, ValueError):
        return  # the samples' stream says why, if anything went wrong


def run_foxglove(a: argparse.Namespace) -> int:
    try:
        import foxglove  # noqa: F401
    except ImportError:
        why = "orccadctl foxglove needs foxglove-sdk: pip install 'orccadd[foxglove]'"
        print(error_line(why), file=sys.stderr)
        return EXIT_ERROR
    try:
        with Client(a.socket) as c:
            items = c.stream("monitor", signals=SIGNALS, rate_hz=a.rate)
            labels = next(items)["signals"][1:]  # after t_s
            view = LiveView(labels, a.port)
            try:
                print(f"foxglove: ws://{HOST}:{view.port} (Foxglove: Open connection > Foxglove WebSocket)")
                sys.stdout.flush()
                threading.Thread(target=_follow_events, args=(a.socket, view), daemon=True).start()
                for item in items:
                    view.sample(float(item["t_s"]), list(item["values"]))
            finally:
                view.stop()
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except (ClientError, OSError, StopIteration) as e:
        print(error_line(str(e) or "the daemon ended the stream"), file=sys.stderr)
        return EXIT_ERROR
    return EXIT_OK
