"""The command daemon as a peer of a cell over Zenoh (`[cell]` in the robot config).

It publishes what `orccadctl` reads on the socket (status, joint states, events), decimated, from
this process: the real-time threads never touch Zenoh. It declares a liveliness token (a daemon
gone is lost to the others within Zenoh's lease) and answers request lines on two queryables:
`read` (read-role commands) and `control` (every command), the second reached only by peers
whose certificate holds the control role (the access control of `cellnet.zconfig`). A request
goes through the socket's table and checks (`CommandDaemon.answer`); `abort` and `stop` go
straight to the real-time process's urgent socket from Zenoh's own thread, as `orccadctl` sends
them. A malformed request gets an error reply; a malformed sample is dropped with a log line.

What a peer may cost it is bounded (`cmdd.cellguard`): the signals it takes (`SignalIntake`:
control peers only, the mission's declared inputs, a rate per peer, a size), the requests served
at once on each key (beyond: `busy` at once). The mission's outputs are published or counted lost
(`OutputLedger`); every drop is counted in `report()` (`status`'s `cell`) and logged, throttled.
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
from orccadd.cmdd.cellguard import InFlight, LogThrottle, OutputLedger, SignalIntake
from orccadd.config.cellnet import CellNetConfig
from orccadd.wire.commands import MAX_LINE, URGENT_COMMANDS, ProtocolError, Role, error_reply, parse_request

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger("orccadd.cmdd.cell")

URGENT_WAIT_S = 2.0
ARRIVALS_MAX = 10_000  # peers' signals waiting for the real-time process (beyond: dropped, counted)
REPORT_S = 1.0  # the log's summaries and the outputs' ledger, this often
Answer = Callable[[bytes, Role, str], Coroutine[Any, Any, dict[str, Any]]]


class CellPeer:
    """One daemon's Zenoh session and what it declares. `answer(line, role, who)` serves a request
    line; `urgent_path` is the real-time process's urgent socket.

    What a peer may cost it is bounded: a peer's signals are taken only if it holds the control
    role, the loaded mission declares that input from it (`mission_changed`), and it keeps within
    `signal_rate_hz`/`signal_burst`; requests on each queryable at most `read_requests_max` /
    `control_requests_max` at once. What is dropped is counted (`report`) and said, the same
    words at most `LogThrottle.burst` times per window, then how many more."""

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
        self.cell_outputs: frozenset[str] = frozenset()  # the mission's outputs to the cell
        self.out_seq = 0
        self.ros: Any = None  # a `cellnet.ros2.Ros2Node` with `ros2 = true`
        # (peer, signal, "signal" | "lost") to the real-time process from Zenoh's thread; False:
        # not sent (queued instead). The command daemon sets it.
        self.deliver_now: Callable[[str, str, str], bool] = lambda peer, name, what: False
        self.say = LogThrottle(log)
        self.intake = SignalIntake(net, self.say)  # which signals are taken, what is dropped
        self.requests = {
            Role.READ: InFlight(net.read_requests_max),
            Role.CONTROL: InFlight(net.control_requests_max),
        }
        self.outputs = OutputLedger()
        self.published = 0
        self.not_published = 0
        self.trace_lost = 0  # trace records the cell's pump did not see (outputs unchecked)
        self.closing = False
        self.reporter: asyncio.Task[None] | None = None

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
        self.reporter = self.loop.create_task(self._report_every(REPORT_S))
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
        self.closing = True  # Zenoh's threads may still call back: they do nothing now
        if self.reporter is not None:
            self.reporter.cancel()
            self.reporter = None
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
        a sequence number (a subscriber drops a duplicate and logs a gap). One that cannot be
        published (the session closing) is counted and said; so is one the real-time process
        emitted (its trace shows it) and never told of (`OutputLedger`). From the event loop."""
        now = time.monotonic()
        self.outputs.pushed(name, now)
        try:
            self._publish(name, mission)
        except Exception as e:  # a session closing: the peers see it lost
            self.not_published += 1
            self.say(
                "cell: outputs not published",
                logging.WARNING,
                "cell: output %s not published: %s: %s (%d so far)",
                name,
                type(e).__name__,
                e,
                self.not_published,
            )
            return
        self.published += 1

    def _publish(self, name: str, mission: str) -> None:
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

    def traced(self, event: dict[str, Any]) -> None:
        """A trace event (decoded): an instant that emitted an output to the cell is one the
        real-time process must have told of (`emit`). From the event loop."""
        if event.get("kind") != "instant" or not self.cell_outputs:
            return
        now = time.monotonic()
        for action in event.get("actions", []):
            if action.startswith("emit ") and action[5:] in self.cell_outputs:
                self.outputs.traced(action[5:], now)

    def untraced(self, records: int) -> None:
        """The trace ring overran: `records` records this daemon did not see, the outputs they
        show not checked against what was published; counted and said. From the event loop."""
        self.trace_lost += records
        self.say(
            "cell: trace records not seen",
            logging.WARNING,
            "cell: the trace overran: %d record(s) not seen, outputs to the cell in them not checked "
            "(%d in all)",
            records,
            self.trace_lost,
        )

    def mission_changed(self, mission: dict[str, Any] | None) -> None:
        """The loaded mission's description (`describe`'s `mission`; None: none): the inputs it
        takes from peers (signals of no other name or peer are dropped unstored) and its outputs
        to the cell. From the event loop."""
        m = mission or {}
        self.intake.mission_changed(frozenset((str(p), str(n)) for n, p in m.get("remote_inputs", [])))
        self.cell_outputs = frozenset(str(n) for n in m.get("cell_outputs", []))

    def report(self) -> dict[str, Any]:
        """What the cell cost and what was dropped, for `status`'s `cell` section: signals by peer
        (`taken`, and dropped: `not_control`, `undeclared`, `over_rate`, `malformed`, `duplicate`,
        `queue_full`; `gaps`, `restarts` taken), the mission's outputs (`published`,
        `not_published`, `lost`, `unchecked_trace_records`), the requests on each key
        (`in_flight`, `max`, `served`, `busy`)."""
        return {
            "signals": self.intake.counts.report(),
            "signal_rate_hz": self.net.signal_rate_hz,
            "signal_burst": self.net.signal_burst,
            "outputs": {
                "published": self.published,
                "not_published": self.not_published,
                "lost": self.outputs.lost,
                "unchecked_trace_records": self.trace_lost,
            },
            "requests": {
                keys.READ: self.requests[Role.READ].report(),
                keys.CONTROL: self.requests[Role.CONTROL].report(),
            },
        }

    async def _report_every(self, period_s: float) -> None:
        """The outputs traced and never told of, counted and said; the log's summaries."""
        while True:
            await asyncio.sleep(period_s)
            now = time.monotonic()
            lost = self.outputs.expire(now)
            if lost:
                self.say(
                    "cell: outputs lost",
                    logging.ERROR,
                    "cell: %d output(s) to the cell emitted and NOT published: the real-time process's "
                    "word of them did not reach the command daemon (%d in all)",
                    lost,
                    self.outputs.lost,
                )
            self.say.flush()

    # ---- peers -----------------------------------------------------------------------------
    def _on_signal(self, sample: zenoh.Sample) -> None:  # Zenoh's thread
        """A peer's signal, to the real-time process if `intake` admits it."""
        if self.closing:
            return
        key = str(sample.key_expr)
        try:
            peer = keys.robot_of(self.net.name, key)
        except ValueError:  # not under the subscription's key expression: cannot happen
            return
        if peer == self.net.robot:
            return
        name = key.rsplit("/", 1)[1]
        if self.intake.admit(peer, name, sample.payload, key):
            self._arrive(peer, name, "signal")

    def _on_liveliness(self, sample: zenoh.Sample) -> None:  # Zenoh's thread
        import zenoh

        if self.closing:
            return
        try:
            peer = keys.robot_of(self.net.name, str(sample.key_expr))
        except ValueError:
            return
        if peer == self.net.robot:
            return
        who = self.intake.who(peer)
        if sample.kind == zenoh.SampleKind.DELETE:
            words = "cell %s: lost %s (its liveliness token is gone)"
            self.say(f"cell: {who} lost", logging.WARNING, words, self.net.name, peer[:64])
            self._arrive(peer, "", "lost")
        else:
            self.say(f"cell: {who} there", logging.INFO, "cell %s: %s is there", self.net.name, peer[:64])
            self._arrive(peer, "", "joined")

    def _arrive(self, peer: str, name: str, what: str) -> None:
        """From Zenoh's thread: straight to the real-time process if nothing waits before it
        (`deliver_now`: one datagram on the link, no hop through this process's event loop),
        else after what waits, in order. A signal sent straight costs the event loop nothing."""
        assert self.loop is not None
        delivered = what != "joined" and self.arrivals.empty() and self.deliver_now(peer, name, what)
        if delivered and what == "signal":
            return
        with contextlib.suppress(RuntimeError):  # the loop closed: the daemon is stopping
            self.loop.call_soon_threadsafe(self.queue, (peer, name, what), delivered)

    def queue(self, item: tuple[str, str, str], delivered: bool = False) -> None:
        peer, _, what = item
        if what == "joined":
            self.alive.add(peer)
            self.intake.joined(peer)
        elif what == "lost":
            self.alive.discard(peer)
        if delivered:
            return
        try:
            self.arrivals.put_nowait(item)
        except asyncio.QueueFull:
            who = self.intake.who(peer)
            self.intake.counts.add(who, "queue_full")
            self.say(
                f"cell: arrivals from {who} dropped (queue_full)",
                logging.ERROR,
                "cell: %s from %s dropped: %d waiting already for the real-time process",
                item[1] or what,
                peer[:64],
                ARRIVALS_MAX,
            )

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
        chunk = keys.CONTROL if role is Role.CONTROL else keys.READ
        who = f"a cell peer on {self.key(chunk)}"
        gate = self.requests[role]
        setting = f"{chunk}_requests_max"

        def on_query(query: zenoh.Query) -> None:  # Zenoh's thread
            if self.closing:
                return
            payload = query.payload
            if payload is not None and len(payload) > MAX_LINE:  # not copied, not decoded
                self._reply(query, error_reply(None, f"request longer than {MAX_LINE} bytes"))
                return
            line = payload.to_bytes() if payload is not None else b""
            if role is Role.CONTROL and self._urgent(line):
                self._reply(query, self._serve_urgent(line))
                return
            if not gate.enter():
                self._busy(query, line, chunk, gate, setting)
                return
            try:
                assert self.loop is not None
                self.loop.call_soon_threadsafe(self._serve, query, line, role, who)
            except RuntimeError:  # the loop closed: the daemon is stopping
                gate.leave()

        return on_query

    def _busy(self, query: zenoh.Query, line: bytes, chunk: str, gate: InFlight, setting: str) -> None:
        """A request beyond the bound: an error reply at once (nothing queued), counted and said."""
        why = (
            f"busy: {gate.limit} requests already in flight on {self.net.robot}'s {chunk} key "
            f"(its bound: [cell] {setting}); try again"
        )
        self._reply(query, error_reply(request_id(line), why))
        self.say(
            f"cell: requests on {chunk} refused (busy)",
            logging.WARNING,
            "cell: a request on %s refused: %s",
            chunk,
            why,
        )

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
            self.say(
                "cell: urgent socket unused",
                logging.INFO,
                "urgent socket: %s; through the command daemon",
                e,
            )
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
        finally:
            self.requests[role].leave()
        self._reply(query, reply)

    def _reply(self, query: zenoh.Query, reply: dict[str, Any]) -> None:
        try:
            query.reply(query.key_expr, json.dumps(reply, separators=(",", ":")))
        except Exception as e:  # the querier gave up (timeout): nothing to answer
            self.say(
                "cell: replies not sent",
                logging.INFO,
                "cell: a reply to %s could not be sent: %s",
                query.key_expr,
                e,
            )
        finally:
            with contextlib.suppress(Exception):
                query.drop()  # type: ignore[no-untyped-call]


def request_id(line: bytes) -> Any:
    """A request line's id, if it has one that can be read (for an error reply to carry)."""
    try:
        return parse_request(line)[0]
    except ProtocolError as e:
        return e.rid


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
