"""A command daemon's part in a cell of robot PCs over Zenoh (`[cell]`): a plug-in beside the
command daemon, which reaches the real-time process through the daemon's one link (`RtLink`)
and reads the rest from the daemon's shared memory as the daemon does.

- Its Zenoh peer (`CellPeer`) answers the cell's requests with the daemon's own `answer`.
- The peers' signals and losses go to the real-time process as the loaded mission takes them:
  straight from Zenoh's thread as a one-way `cell_input` when the link takes it, else queued
  and sent in arrival order.
- The mission's outputs to the cell (the real-time process pushes them) are published; so are
  every trace event, the status and the joint states, each at its rate.

A cell that cannot be joined (Zenoh missing, an endpoint taken, a bad certificate) is logged;
the robot is served on its socket all the same.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any, Protocol

from orccadd.cellnet import keys
from orccadd.cmdd import views
from orccadd.cmdd.cellpeer import Answer, CellPeer
from orccadd.cmdd.rtlink import RtLink
from orccadd.config.cellnet import CellNetConfig
from orccadd.wire.schema import H
from orccadd.wire.socketdir import urgent_socket_path
from orccadd.wire.telemetry import RingReader, TelemetryBlock

log = logging.getLogger("orccadd.cmdd")

# the publishing loop sleeps at least this long (no spinning); it wakes at each joint state's
# own deadline: a floor of 5 ms here held joints_hz 500 to ~180 a second
CELL_TICK_S = 0.0005
CELL_CATCH_UP_S = 0.05  # joint states late by up to this are still sent (the newest state each)
CELL_STATUS_MIN_S = 0.1  # a status on an event: not more often (its timing figures cost ~1 ms)
CELL_TRACE_S = 0.05  # ... and at least this often (the trace's events to the cell)


class Daemon(Protocol):
    """What the plug-in takes from the command daemon (`server.CommandDaemon`)."""

    rt: RtLink  # the one link to the real-time process
    socket_path: str  # its public socket (the urgent one is beside it)
    block: TelemetryBlock  # the daemon's own block: the status and the trace
    desc: dict[str, Any]  # the real-time process's `describe`, as of the last `refresh`

    @property
    def tel(self) -> TelemetryBlock: ...  # the block of the resource a client addresses by default
    @property
    def answer(self) -> Answer: ...  # a request line, checked and served as the socket's are
    async def refresh(self, timeout_s: float | None = ...) -> None: ...
    def decode_trace(self, rec: Any) -> dict[str, Any]: ...
    def units(self) -> list[tuple[dict[str, Any], TelemetryBlock]]: ...
    def log_state(self) -> dict[str, Any] | None: ...
    def status_of(self, log_state: dict[str, Any] | None) -> dict[str, Any]: ...


class CellPlugin:
    """The daemon's Zenoh peer and the two tasks that feed it and the real-time process."""

    def __init__(self, daemon: Daemon, net: CellNetConfig, peer: CellPeer) -> None:
        self.daemon = daemon
        self.net = net
        self.peer = peer
        self._arrivals = asyncio.create_task(self._deliver_queued())
        self._publish = asyncio.create_task(self._publish_loop())

    @classmethod
    async def join(cls, daemon: Daemon, net: CellNetConfig) -> CellPlugin | None:
        """The daemon in the cell `net`, or None (said in the log) where it cannot join."""
        peer = CellPeer(net, daemon.answer, urgent_socket_path(daemon.socket_path))
        try:
            await peer.open()
        except Exception as e:  # ImportError, zenoh.ZError: the daemon carries on without it
            log.error("cell %s: cannot join: %s: %s", net.name, type(e).__name__, e)
            peer.close()
            return None
        plugin = cls(daemon, net, peer)
        link = daemon.rt
        link.on_push = plugin._pushed
        link.on_refused = lambda reply: peer.say(
            "cell: inputs refused",
            logging.WARNING,
            "cell: an input from the cell refused by the real-time process: %s",
            reply.get("error"),
        )
        peer.deliver_now = plugin._deliver_now
        peer.mission_changed(daemon.desc.get("mission"))
        return plugin

    def close(self) -> None:
        self._publish.cancel()
        self._arrivals.cancel()
        self.peer.close()

    # ---- to the real-time process ---------------------------------------------------------
    def _mission_input(self, who: str, name: str, what: str) -> str:
        """The loaded mission's input for a peer's signal or loss ("" if it takes none)."""
        mission = self.daemon.desc.get("mission") or {}
        if what == "signal":
            return name if [name, who] in mission.get("remote_inputs", []) else ""
        if what == "lost":
            return next((n for n, p in mission.get("lost_inputs", []) if p == who), "")
        return ""

    def _deliver_now(self, who: str, name: str, what: str) -> bool:
        """From Zenoh's thread: a `cell_input` one-way on the link (the real-time process serves
        it on arrival, traces it, and replies only to refuse it, `RtLink.on_refused`); False if
        it could not be sent (the peer queues it then: `_deliver_queued`)."""
        taken = self._mission_input(who, name, what)
        if not taken:
            return True  # nothing to deliver: done
        return self.daemon.rt.send_oneway("cell_input", {"input": taken, "peer": who})

    async def _deliver_queued(self) -> None:
        """Peers' signals and losses that could not go straight, one at a time in arrival order:
        each one the running mission takes is one input of one instant (`cell_input`)."""
        while True:
            who, name, what = await self.peer.arrivals.get()
            name = self._mission_input(who, name, what)
            if not name:
                continue
            reply = await self.daemon.rt.call("cell_input", {"input": name, "peer": who})
            if not reply.get("ok"):
                self.peer.say(
                    f"cell: {name} from {who} not taken",
                    logging.WARNING,
                    "cell: %s from %s not taken: %s",
                    name,
                    who,
                    reply.get("error"),
                )

    # ---- to the cell ----------------------------------------------------------------------
    def _pushed(self, msg: dict[str, Any]) -> None:
        """The real-time process's own news: a mission's output to the cell, emitted just now."""
        if msg.get("push") == "cell_output" and isinstance(msg.get("name"), str):
            self.peer.emit(msg["name"], str(msg.get("mission", "")))  # one not published: counted, said

    def _run_started(self) -> None:
        """A run began: a peer it must see is not there now, so its loss is this run's first news."""
        mission = self.daemon.desc.get("mission") or {}
        for _, who in mission.get("lost_inputs", []):
            if who not in self.peer.alive:
                self.peer.queue((who, "", "lost"))

    async def _publish_loop(self) -> None:
        """Every trace event as it comes (and the status with it), the status at `status_hz`,
        the joint states at `joints_hz` (each at its deadline, on a fixed grid: the rate asked
        is the rate sent; `benchmarks/cell_joints.py`)."""
        d, peer = self.daemon, self.peer
        trace = RingReader(d.block.trace, d.block.header, H.TRACE_HEAD, from_now=True)
        joints_s = 1.0 / self.net.joints_hz if self.net.joints_hz else float("inf")
        status_s = 1.0 / self.net.status_hz
        next_joints = next_status = time.monotonic()
        status_at = 0.0
        while True:
            try:
                seen = trace.lost
                new = trace.poll()
                if trace.lost > seen:  # the ring overran: the outputs in those records unchecked
                    peer.untraced(trace.lost - seen)
                if len(new):
                    await d.refresh()
                    for rec in new:
                        event = d.decode_trace(rec)
                        peer.put(keys.EVENTS, event)
                        peer.traced(event)  # an output it emitted: told of, or counted lost
                        if event.get("command") == "start":
                            self._run_started()
                now = time.monotonic()
                if now >= next_status or (len(new) and now - status_at >= CELL_STATUS_MIN_S):
                    await d.refresh()
                    peer.put(keys.STATUS, d.status_of(d.log_state()))
                    next_status = max(next_status + status_s, now)
                    status_at = now
                if now >= next_joints:
                    peer.put(keys.JOINTS, views.joint_states(d.tel, d.desc, d.units()))
                    # on the deadlines' grid: one missed (the loop busy) is made up at once, up
                    # to `CELL_CATCH_UP_S` behind; beyond, the grid starts again from now
                    next_joints += joints_s
                    if next_joints < now - CELL_CATCH_UP_S:
                        next_joints = now + joints_s
            except asyncio.CancelledError:
                raise
            except Exception as e:  # a publication lost must not end the others
                peer.say(
                    "cell: publishing failed",
                    logging.WARNING,
                    "cell: publishing: %s: %s",
                    type(e).__name__,
                    e,
                )
            nxt = min(next_joints, next_status, time.monotonic() + CELL_TRACE_S)
            await asyncio.sleep(max(CELL_TICK_S, nxt - time.monotonic()))
