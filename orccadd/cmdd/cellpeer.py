"""The command daemon as a peer of a cell over Zenoh (`[cell]` in the robot config).

It publishes what `orccadctl` reads on the socket (status, joint states, events), decimated, from
this process: the real-time threads never touch Zenoh. It declares a liveliness token (a daemon
gone is lost to the others within Zenoh's lease) and answers request lines on two queryables:
`read` (read-role commands) and `control` (every command), the second reached only by peers
whose certificate holds the control role (the access control of `cellnet.zconfig`). A request
goes through the socket's table and checks (`CommandDaemon.answer`); `abort` and `stop` go
straight to the real-time process's urgent socket from Zenoh's own thread, as `orccadctl` sends
them. A malformed request gets an error reply; a malformed sample is dropped with a log line.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import logging
import socket
import time
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

from orccadd.cellnet import keys
from orccadd.cellnet.zconfig import to_json5, zenoh_config
from orccadd.config.cellnet import CellNetConfig
from orccadd.wire.commands import MAX_LINE, URGENT_COMMANDS, ProtocolError, Role, error_reply, parse_request

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger("orccadd.cmdd.cell")

URGENT_WAIT_S = 2.0
ARRIVALS_MAX = 10_000  # peers' signals waiting for the real-time process (beyond: dropped, logged)
SIGNAL_MAX = 4096  # bytes of a signal's payload
Answer = Callable[[bytes, Role, str], Coroutine[Any, Any, dict[str, Any]]]


class CellPeer:
    """One daemon's Zenoh session and what it declares. `answer(line, role, who)` serves a request
    line; `urgent_path` is the real-time process's urgent socket."""

    def __init__(self, net: CellNetConfig, answer: Answer, urgent_path: str) -> None:
        self.net = net
        self.answer = answer
        self.urgent_path = urgent_path
        self.session: zenoh.Session | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self.declared: list[Any] = []
        self.pubs: dict[str, Any] = {}
        self.pending: set[asyncio.Task[None]] = set()
        # the cell's side of missions: peers' signals and losses, in arrival order, for the
        # real-time process (one consumer: per-link order kept); peers alive now
        self.arrivals: asyncio.Queue[tuple[str, str, str]] = asyncio.Queue(maxsize=ARRIVALS_MAX)
        self.alive: set[str] = set()
        self.last_seq: dict[tuple[str, str], int] = {}  # (peer, signal) -> last sequence number taken
        self.out_seq = 0
        self.ros: Any = None  # a `cellnet.ros2.Ros2Node` with `ros2 = true`
        # (peer, signal, "signal" | "lost") to the real-time process from Zenoh's thread; False:
        # not sent (queued instead). The command daemon sets it.
        self.deliver_now: Callable[[str, str, str], bool] = lambda peer, name, what: False

    def key(self, *chunks: str) -> str:
        return keys.robot_key(self.net.name, self.net.robot, *chunks)

    async def open(self) -> None:
        import zenoh  # the `[cell]` extra: only a daemon with a cell needs it

        self.loop = asyncio.get_running_loop()
        conf = zenoh.Config.from_json5(to_json5(zenoh_config(self.net, daemon=True)))
        self.session = await asyncio.to_thread(zenoh.open, conf)
        s = self.session
        for chunk in (keys.STATUS, keys.JOINTS, keys.EVENTS):
            self.pubs[chunk] = s.declare_publisher(self.key(chunk))
        self.declared.append(s.declare_queryable(self.key(keys.READ), self._on_query(Role.READ)))
        if self.net.secured:  # without TLS nobody can be trusted with control: no such key
            self.declared.append(s.declare_queryable(self.key(keys.CONTROL), self._on_query(Role.CONTROL)))
        self.declared.append(
            s.declare_subscriber(keys.every_robot(self.net.name, keys.SIGNAL, "*"), self._on_signal)
        )
        self.declared.append(
            s.liveliness().declare_subscriber(
                keys.every_robot(self.net.name, keys.ALIVE), self._on_liveliness, history=True
            )
        )
        self.declared.append(s.liveliness().declare_token(self.key(keys.ALIVE)))
        if self.net.ros2:
            from orccadd.cellnet.ros2 import Ros2Node

            self.ros = Ros2Node(s, self.net.robot, "orccadd", self.net.ros2_domain_id)
            log.info("ROS 2 (rmw_zenoh): node %s%s", self.ros.namespace, "/orccadd")
        log.info(
            "cell %s: peer %s (zid %s), listening on %s%s",
            self.net.name,
            self.net.robot,
            s.info.zid(),
            ", ".join(self.net.listen) or "loopback",
            "" if self.net.secured else "; no TLS: read-only",
        )

    def close(self) -> None:
        if self.ros is not None:
            with contextlib.suppress(Exception):
                self.ros.close()
            self.ros = None
        for d in self.declared:
            with contextlib.suppress(Exception):
                d.undeclare()
        self.declared.clear()
        for p in self.pubs.values():
            with contextlib.suppress(Exception):
                p.undeclare()
        self.pubs.clear()
        if self.session is not None:
            with contextlib.suppress(Exception):
                self.session.close()  # type: ignore[no-untyped-call]
            self.session = None

    def emit(self, name: str, mission: str) -> None:
        """The mission emitted `name`, an output to the cell: published reliably, in order, with
        a sequence number (a subscriber drops a duplicate and logs a gap)."""
        assert self.session is not None
        key = self.key(keys.SIGNAL, name)
        pub = self.pubs.get(key)
        if pub is None:
            import zenoh

            pub = self.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
                express=True,
            )
            self.pubs[key] = pub
        self.out_seq += 1
        pub.put(json.dumps({"seq": self.out_seq, "wall_s": time.time(), "mission": mission}))

    # ---- peers -----------------------------------------------------------------------------
    def _on_signal(self, sample: zenoh.Sample) -> None:  # Zenoh's thread
        key = str(sample.key_expr)
        try:
            peer = keys.robot_of(self.net.name, key)
            name = key.rsplit("/", 1)[1]
            raw = sample.payload.to_bytes()
            if len(raw) > SIGNAL_MAX:
                raise ValueError(f"{len(raw)} bytes")
            msg = json.loads(raw)
            seq = msg["seq"] if isinstance(msg, dict) else None
            if not isinstance(seq, int) or isinstance(seq, bool) or seq < 1:
                raise ValueError("no positive integer `seq`")
        except (ValueError, KeyError, UnicodeDecodeError, RecursionError) as e:
            log.warning("cell: a malformed signal on %s dropped: %s", key[:200], str(e)[:200])
            return
        if peer == self.net.robot:
            return
        last = self.last_seq.get((peer, name), 0)
        if seq <= last:
            log.info("cell: %s from %s: sequence %d again (after %d): dropped", name, peer, seq, last)
            return
        if last and seq > last + 1:
            log.warning("cell: %s from %s: %d signal(s) missed before %d", name, peer, seq - last - 1, seq)
        self.last_seq[(peer, name)] = seq
        self._arrive(peer, name, "signal")

    def _on_liveliness(self, sample: zenoh.Sample) -> None:  # Zenoh's thread
        import zenoh

        try:
            peer = keys.robot_of(self.net.name, str(sample.key_expr))
        except ValueError:
            return
        if peer == self.net.robot:
            return
        if sample.kind == zenoh.SampleKind.DELETE:
            log.warning("cell %s: lost %s (its liveliness token is gone)", self.net.name, peer)
            self._arrive(peer, "", "lost")
        else:
            log.info("cell %s: %s is there", self.net.name, peer)
            self._arrive(peer, "", "joined")

    def _arrive(self, peer: str, name: str, what: str) -> None:
        """From Zenoh's thread: straight to the real-time process if nothing waits before it
        (`deliver_now`: one datagram on the link, no hop through this process's event loop),
        else after what waits, in order."""
        assert self.loop is not None
        delivered = what != "joined" and self.arrivals.empty() and self.deliver_now(peer, name, what)
        self.loop.call_soon_threadsafe(self.queue, (peer, name, what), delivered)

    def queue(self, item: tuple[str, str, str], delivered: bool = False) -> None:
        peer, _, what = item
        if what == "joined":
            self.alive.add(peer)
            self.last_seq = {k: v for k, v in self.last_seq.items() if k[0] != peer}  # a new run of it
        elif what == "lost":
            self.alive.discard(peer)
        if delivered:
            return
        try:
            self.arrivals.put_nowait(item)
        except asyncio.QueueFull:
            log.error("cell: %s from %s dropped: %d waiting already", item[1] or what, peer, ARRIVALS_MAX)

    def put(self, chunk: str, value: Any) -> None:
        pub = self.pubs.get(chunk)
        if pub is not None:
            pub.put(json.dumps(value, separators=(",", ":")))
        if self.ros is not None:
            if chunk == keys.JOINTS:
                self._ros_joints(value)
            elif chunk == keys.EVENTS:
                self.ros.publish_log(time.time_ns(), *ros_log(value))

    def _ros_joints(self, js: dict[str, Any]) -> None:
        """One JointState of every resource's joints (named `resource/joint` when there are several)."""
        units = js.get("resources", [])
        if not units:
            return
        several = len(units) > 1
        names = [f"{u['name']}/{j}" if several else j for u in units for j in u["joints"]]
        q = [x for u in units for x in u["q"]]
        dq = [x for u in units for x in u["dq"]]
        tau = [x for u in units for x in u["tau"]]
        self.ros.publish_joint_state(time.time_ns(), names, q, dq, tau)

    # ---- requests --------------------------------------------------------------------------
    def _on_query(self, role: Role) -> Callable[[zenoh.Query], None]:
        who = f"a cell peer on {self.key(keys.CONTROL if role is Role.CONTROL else keys.READ)}"

        def on_query(query: zenoh.Query) -> None:  # Zenoh's thread
            line = query.payload.to_bytes() if query.payload is not None else b""
            if len(line) > MAX_LINE:
                self._reply(query, error_reply(None, f"request longer than {MAX_LINE} bytes"))
                return
            if role is Role.CONTROL and self._urgent(line):
                self._reply(query, self._serve_urgent(line))
                return
            assert self.loop is not None
            self.loop.call_soon_threadsafe(self._serve, query, line, role, who)

        return on_query

    @staticmethod
    def _urgent(line: bytes) -> bool:
        try:
            return parse_request(line)[1] in URGENT_COMMANDS
        except ProtocolError:
            return False

    def _serve_urgent(self, line: bytes) -> dict[str, Any]:
        """`abort` or `stop` on the real-time process's urgent socket, from this thread; the
        command daemon's own queue if that socket is not there or refuses."""
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC) as s:
                s.settimeout(URGENT_WAIT_S)
                s.connect(self.urgent_path)
                s.sendall(line.rstrip(b"\n") + b"\n")
                buf = b""
                while not buf.endswith(b"\n"):
                    chunk = s.recv(65536)
                    if not chunk:
                        break
                    buf += chunk
            reply = json.loads(buf)
            if isinstance(reply, dict) and reply.get("id") == parse_request(line)[0]:
                return reply
        except (OSError, ValueError, ProtocolError) as e:
            log.info("urgent socket: %s; through the command daemon", e)
        assert self.loop is not None
        fut: concurrent.futures.Future[dict[str, Any]] = asyncio.run_coroutine_threadsafe(
            self.answer(line, Role.CONTROL, "a cell peer"), self.loop
        )
        try:
            return fut.result(URGENT_WAIT_S * 5)
        except Exception as e:
            return error_reply(None, f"{type(e).__name__}: {e}")

    def _serve(self, query: zenoh.Query, line: bytes, role: Role, who: str) -> None:
        task = asyncio.get_running_loop().create_task(self._answer_query(query, line, role, who))
        self.pending.add(task)
        task.add_done_callback(self.pending.discard)

    async def _answer_query(self, query: zenoh.Query, line: bytes, role: Role, who: str) -> None:
        try:
            reply = await self.answer(line, role, who)
        except Exception as e:  # a bug must not leave the peer without an answer
            log.exception("cell request failed")
            reply = error_reply(None, f"internal error: {type(e).__name__}: {e}")
        self._reply(query, reply)

    def _reply(self, query: zenoh.Query, reply: dict[str, Any]) -> None:
        try:
            query.reply(query.key_expr, json.dumps(reply, separators=(",", ":")))
        except Exception as e:  # the querier gave up (timeout): nothing to answer
            log.info("cell: a reply to %s could not be sent: %s", query.key_expr, e)
        finally:
            with contextlib.suppress(Exception):
                query.drop()  # type: ignore[no-untyped-call]


def ros_log(event: dict[str, Any]) -> tuple[int, str]:
    """(rcl_interfaces/msg/Log level, text) of one trace event."""
    kind = event.get("kind")
    if kind == "fault":
        return 40, f"fault: {json.dumps(event.get('fault'))}"
    if kind == "instant":
        inputs, actions = ", ".join(event.get("inputs", [])), ", ".join(event.get("actions", []))
        text = (
            f"{event.get('mission')}: instant {event.get('from')}->{event.get('to')} "
            f"inputs {{{inputs}}} actions {{{actions}}}"
        )
        return (30 if "t3" in event.get("input_kinds", []) else 20), text
    if kind == "event":
        return (30 if event.get("event_kind") == "t3" else 20), f"event {event.get('event')}"
    return 20, f"command {event.get('command')}"
