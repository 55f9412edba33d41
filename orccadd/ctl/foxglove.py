"""`orccadctl foxglove [--port N]`: a live view of a running orccadd in Foxglove.

Follows the daemon's `monitor` stream (q, dq, tau, cmd at `--rate`) and its reactive trace
(`events --follow`), and serves them over the Foxglove WebSocket protocol bound to 127.0.0.1 only
(`orccadd.ctl.livews`): to the user who started it (and root) only, never to another local user
holding no role on the daemon, nor to a web page of another origin than Foxglove's. From another
machine, tunnel the port over SSH. Channels as in a log's MCAP, with the same schemas: `/q`,
`/dq`, `/tau`, `/cmd` (units in their schemas), `/joint_states` (foxglove.JointStates, for a URDF
layer of the 3D panel) and `/events` (foxglove.Log). A station: each resource's channels named by it
(`/left/q`), every joint on `/joint_states`.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

from orccadd.ctl.client import Client, ClientError, socket_help
from orccadd.ctl.format import error_line
from orccadd.fault import cause_words
from orccadd.wire import foxglove_schemas as sch
from orccadd.wire.schema import exception_of

HOST = "127.0.0.1"  # never another address
SIGNALS = ["q", "dq", "tau", "cmd"]
UNITS = {"q": "rad", "dq": "rad/s", "tau": "N.m", "cmd": "rad, rad/s or N.m (the command mode's)"}
EXIT_OK, EXIT_ERROR, EXIT_INTERRUPTED = 0, 2, 130


def add_parser(sub: Any) -> None:
    """The `foxglove` subcommand (for orccadctl's parser)."""
    text = "serve the live state and events to Foxglove over a WebSocket on 127.0.0.1 (to you only)"
    p = sub.add_parser("foxglove", help=text, description=text)
    p.add_argument("--socket", default=None, metavar="PATH", help=socket_help())
    p.add_argument("--port", type=int, default=8765, help="the WebSocket's port on 127.0.0.1 (0: any free)")
    p.add_argument("--rate", type=float, default=50.0, help="samples per second")
    p.add_argument(
        "--allow-origin",
        action="append",
        default=[],
        metavar="ORIGIN",
        help="a web origin allowed besides Foxglove's app (https://app.foxglove.dev) and native clients",
    )
    p.set_defaults(func=run_foxglove)


class LiveView:
    """The WebSocket server and its channels."""

    def __init__(self, labels: list[str], port: int, extra_origins: tuple[str, ...] = ()) -> None:
        from orccadd.ctl.livews import FOXGLOVE_ORIGINS, Channel, LiveServer

        self.lock = threading.Lock()
        self.stopped = False
        self.groups: dict[str, tuple[int, list[tuple[str, int]]]] = {}
        fields: dict[str, list[str]] = {}
        for i, label in enumerate(labels):
            base, _, joint = label.partition(".")
            self.groups.setdefault(base, (len(self.groups) + 1, []))[1].append((joint or "value", i))
            fields.setdefault(base, []).append(joint or "value")
        channels = []
        for base, (cid, _) in self.groups.items():
            signal = base.rpartition("/")[2]  # a station's `left/q` is a `q`
            unit = UNITS.get(signal, "1")
            schema = sch.group_schema(signal, fields[base], unit)
            channels.append(Channel(cid, f"/{base}", f"orccadd.{signal}", schema))
        self.joint_states_id = len(channels) + 1
        self.events_id = len(channels) + 2
        channels.append(
            Channel(self.joint_states_id, "/joint_states", "foxglove.JointStates", sch.JOINT_STATES_SCHEMA)
        )
        channels.append(Channel(self.events_id, "/events", "foxglove.Log", sch.LOG_SCHEMA))
        self.index = {label: i for i, label in enumerate(labels)}
        # (name on /joint_states, the resource's label prefix, joint): a station's joints all there,
        # a name two resources share told apart by its resource's (`left/elbow_joint`)
        qs = [label.partition(".") for label in labels if label.partition(".")[0].rpartition("/")[2] == "q"]
        names = [joint for _, _, joint in qs]
        self.joints = [
            (sch.joint_state_name(base.rpartition("/")[0], j, names), base.removesuffix("q"), j)
            for base, _, j in qs
        ]
        self.server = LiveServer("orccadd", channels, port, origins=(*FOXGLOVE_ORIGINS, *extra_origins))

    @property
    def port(self) -> int:
        return self.server.port

    def sample(self, t_s: float, values: list[float]) -> None:
        """One monitor sample: every group's channel and the joint states."""
        ns = time.time_ns()
        with self.lock:
            if self.stopped:
                return
            for cid, fields in self.groups.values():
                msg = {"time_s": t_s, **{f: values[i] for f, i in fields}}
                self.server.log(cid, json.dumps(msg).encode(), ns)

            def val(label: str) -> float | None:
                i = self.index.get(label)
                return values[i] if i is not None else None

            joints = [
                {
                    "name": name,
                    "position": val(f"{res}q.{j}"),
                    "velocity": val(f"{res}dq.{j}"),
                    "effort": val(f"{res}tau.{j}"),
                }
                for name, res, j in self.joints
            ]
            states = {"timestamp": sch.stamp(ns), "joints": joints}
            self.server.log(self.joint_states_id, json.dumps(states).encode(), ns)

    def event(self, e: dict[str, Any]) -> None:
        """One trace record as `events` decodes it."""
        ns = time.time_ns()
        kind = str(e.get("kind", "?"))
        if kind == "instant":
            text = f"{'+'.join(e.get('inputs', []))} -> {' '.join(e.get('actions', []))}"
        elif kind == "fault":
            text = f"safe stop: {cause_words(e['fault'])}"
        else:
            text = str(e.get("event", e.get("command", "?")))
        seq = max(int(e.get("seq", 0)), 0)
        msg = {
            "timestamp": sch.stamp(ns),
            "level": sch.level(kind, text, exception_of(e)),
            "message": text,
            "name": f"orccadd.{kind}",
            "file": "",
            "line": seq,
        }
        with self.lock:
            if not self.stopped:
                self.server.log(self.events_id, json.dumps(msg).encode(), ns)

    def stop(self) -> None:
        """Stop serving; returns once the port is closed."""
        with self.lock:
            if self.stopped:
                return
            self.stopped = True
        self.server.stop()


JOIN_S = 5.0  # the events follower, once its connection is closed


def _follow_events(events: Client, view: LiveView) -> None:
    """The daemon's events into the view, until the connection ends (closed by the owner)."""
    try:
        for e in events.stream("events", last=0, follow=True):
            view.event(e)
    except (ClientError, OSError, ValueError):
        return  # closed by the owner; or the samples' stream says why, if anything went wrong


def run_foxglove(a: argparse.Namespace) -> int:
    try:
        import websockets  # noqa: F401
    except ImportError:
        why = "orccadctl foxglove needs websockets: pip install 'orccadd[foxglove]'"
        print(error_line(why), file=sys.stderr)
        return EXIT_ERROR
    try:
        with Client(a.socket) as c:
            items = c.stream("monitor", signals=SIGNALS, rate_hz=a.rate)
            labels = next(items)["signals"][1:]  # after t_s
            view = LiveView(labels, a.port, tuple(getattr(a, "allow_origin", [])))
            try:
                print(f"foxglove: ws://{HOST}:{view.port} (Foxglove: Open connection > Foxglove WebSocket)")
                sys.stdout.flush()
                events = Client(a.socket)
                follower = threading.Thread(target=_follow_events, args=(events, view), name="events")
                follower.start()
                try:
                    for item in items:
                        view.sample(float(item["t_s"]), list(item["values"]))
                finally:  # its connection ended, the follower's stream ends: joined
                    events.interrupt()
                    follower.join(timeout=JOIN_S)
                    events.close()
            finally:
                view.stop()
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except (ClientError, OSError, StopIteration) as e:
        print(error_line(str(e) or "the daemon ended the stream"), file=sys.stderr)
        return EXIT_ERROR
    return EXIT_OK
