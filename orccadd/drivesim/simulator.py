"""N simulated CiA 402 drives on one or more buses, moving one simulated arm.

`DriveSimulator.run()` is the drives' side of the buses in one loop: every frame is handed to
the nodes of its bus, a SYNC runs the cycle of every drive on its bus (synchronous RPDOs
applied, references to the arm, actual values sampled, TPDOs sent), and the arm integrates on
the wall clock in between, so it keeps moving (or falls, braked) whatever the bus does. Faults
are injected with `inject`. The drives are as strict as real ones (`Strictness`: heartbeat
consumer, COB-ID valid bit, supported modes only) unless told otherwise; a mode display that
lags is one such option.

Drives on several buses (`AxisSpec.bus`) share the one arm, so one process serves them all: the
joints are coupled by the arm's dynamics, and one integration in one process keeps them so
(one process per bus would have to share the plant's state and step it in lockstep). Each bus
has its own SYNC: a SYNC on one bus cycles only that bus's drives.
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import can

from orccadd.config.robot import RobotConfig
from orccadd.drivesim.axis import (
    EMCY_FOLLOWING_ERROR,
    EMCY_OVERCURRENT,
    ERR_REG_CURRENT,
    STRICT,
    Axis,
    AxisUnits,
    Strictness,
)
from orccadd.drivesim.plant import DriveTrainArm
from orccadd.drivesim.slave import COB_SYNC, SlaveNode
from orccadd.model import RobotModel

log = logging.getLogger("orccadd.drivesim")

FAULTS = ("overcurrent", "following_error", "heartbeat_silence", "node_silence", "sto", "clear")


@dataclass(frozen=True)
class AxisSpec:
    node_id: int
    eds: str
    units: AxisUnits
    bus: int = 0  # index of its bus in the simulator's `buses`


class DriveSimulator:
    def __init__(
        self,
        cfg: RobotConfig,
        axes: list[AxisSpec],
        bus: can.BusABC | Sequence[can.BusABC],
        strict: Strictness = STRICT,
        bus_names: Sequence[str] = (),
    ) -> None:
        if len(axes) != cfg.dof:
            raise ValueError(f"{len(axes)} drives for a {cfg.dof}-joint arm")
        self.cfg = cfg
        self.buses = [bus] if isinstance(bus, can.BusABC) else list(bus)
        self.bus = self.buses[0]
        self.bus_names = list(bus_names) or [f"bus {k}" for k in range(len(self.buses))]
        self.strict = strict
        self.arm = DriveTrainArm(cfg, RobotModel.from_config(cfg))
        self.lock = threading.Lock()  # held while frames, SYNCs, timers or injections run
        self.nodes = [
            SlaveNode(a.node_id, a.eds, self._sender(self.buses[a.bus]), strict.cob_id_valid_bit)
            for a in axes
        ]
        self.axes = [
            Axis(node, j, self.arm, a.units, strict)
            for j, (node, a) in enumerate(zip(self.nodes, axes, strict=True))
        ]
        self.specs = list(axes)
        # per bus: its nodes and axes (a frame reaches only the nodes of its bus)
        self.bus_nodes = [
            [n for n, a in zip(self.nodes, axes, strict=True) if a.bus == k] for k in range(len(self.buses))
        ]
        self.bus_axes = [
            [x for x, a in zip(self.axes, axes, strict=True) if a.bus == k] for k in range(len(self.buses))
        ]
        self.syncs = 0
        self.bus_syncs = [0] * len(self.buses)
        self.period_s = cfg.control_period_s  # the drives' cycle when their dictionary has none
        self.bus_error = ""
        self._errors_logged: set[str] = set()
        # how long frames waited between the bus and this loop (the hub stamps each frame with
        # the wall clock as it forwards it): a drive on a real bus reads its frames within µs
        self.frame_age_s: deque[float] = deque(maxlen=10_000)
        self._routes: list[dict[int, list[SlaveNode]]] = [{} for _ in self.buses]  # per bus: COB-ID -> nodes
        self._routes_generation = -1
        self.longest_gap_s = 0.0  # longest time between two passes of the loop once SYNCs flow

    def _sender(self, bus: can.BusABC) -> Callable[[can.Message], None]:
        def send(msg: can.Message) -> None:
            try:
                bus.send(msg)
            except (can.CanError, OSError) as e:  # the bus is gone: the drives' own watchdogs act
                self._bus_failed(e)

        return send

    def _send_queued(self) -> None:
        """Hand frames queued by a batching bus (`QueuedSocketcandBus`) to each bus, in order."""
        for bus in self.buses:
            send_queued = getattr(bus, "send_queued", None)
            if send_queued is not None:
                try:
                    send_queued()
                except (can.CanError, OSError) as e:
                    self._bus_failed(e)

    def _bus_failed(self, e: Exception) -> None:
        """Record a bus error; each distinct message logged once (a dead bus fails every call)."""
        self.bus_error = str(e)
        if self.bus_error not in self._errors_logged and len(self._errors_logged) < 16:
            self._errors_logged.add(self.bus_error)
            log.warning("bus error: %s", e)

    def boot(self) -> None:
        now = time.monotonic()
        with self.lock:
            self.arm.step_to(now)
            for node, axis in zip(self.nodes, self.axes, strict=True):
                node.boot(now)
                axis.boot()
            self._send_queued()

    def run(self, stop: Callable[[], bool], poll_s: float = 0.005) -> None:
        """Serve the bus until `stop()` (checked at least every `poll_s`). Frames wake it at
        once; everything already queued is taken in one go, the arm integrated up to now, then
        the frames handled in order (a real drive reads a frame within microseconds: this loop
        must keep up with ~4,000 frames/s at 500 Hz on a shared core)."""
        self.boot()
        batches: list[list[can.Message]] = [[] for _ in self.buses]
        last = time.monotonic()
        while not stop():
            t = time.monotonic()
            if self.syncs:  # (before, resets of whole dictionaries take their time)
                self.longest_gap_s = max(self.longest_gap_s, t - last)
            last = t
            try:
                self._take(batches, poll_s)
            except (can.CanError, OSError, ValueError) as e:
                self._bus_failed(e)
                time.sleep(poll_s)
            now = time.monotonic()
            wall = time.time()
            for batch in batches:
                for msg in batch:
                    if msg.timestamp:
                        self.frame_age_s.append(wall - msg.timestamp)
            with self.lock:
                self.arm.step_to(now)
                for k, batch in enumerate(batches):
                    for msg in batch:
                        self._dispatch(msg, now, k)
                for node, axis in zip(self.nodes, self.axes, strict=True):
                    node.poll(now)
                    axis.poll(now)
                self._send_queued()

    def _take(self, batches: list[list[can.Message]], poll_s: float) -> None:
        """Every frame already queued on every bus, waiting up to `poll_s` for the first."""
        for batch in batches:
            batch.clear()
        buses = self.buses
        if len(buses) == 1:
            ready = [0]
            msg = buses[0].recv(poll_s)
            if msg is None:
                return
            batches[0].append(msg)
        else:  # several buses: whichever has frames (a bus's file descriptor is readable)
            readable, _, _ = select.select([b.fileno() for b in buses], [], [], poll_s)
            ready = [k for k, b in enumerate(buses) if b.fileno() in readable]
        for k in ready:
            msg = buses[k].recv(0.0)
            while msg is not None:
                batches[k].append(msg)
                msg = buses[k].recv(0.0)

    def _dispatch(self, msg: can.Message, now_s: float, bus: int = 0) -> None:
        cob = msg.arbitration_id
        if msg.is_extended_id:
            return
        if cob == COB_SYNC:
            self._sync(now_s, bus)
            return
        generation = sum(node.pdo_generation for node in self.nodes)
        if generation != self._routes_generation:
            for k, nodes in enumerate(self.bus_nodes):
                routes: dict[int, list[SlaveNode]] = {}
                for node in nodes:  # descriptions may give several nodes one COB-ID (e35's)
                    for c in node.unicast_cobs():
                        routes.setdefault(c, []).append(node)
                self._routes[k] = routes
            self._routes_generation = generation
        for node in self._routes[bus].get(cob, self.bus_nodes[bus]):
            node.on_frame(msg, now_s)

    def _sync(self, now_s: float, bus: int = 0) -> None:
        self.syncs += 1
        self.bus_syncs[bus] += 1
        for node in self.bus_nodes[bus]:
            node.on_sync(now_s)
        for axis in self.bus_axes[bus]:
            axis.cycle(now_s, self.period_s)
        for node in self.bus_nodes[bus]:
            node.transmit_sync_pdos()

    def axis_of(self, node_id: int, bus: str = "") -> Axis:
        """The drive with `node_id` (on `bus`, by name, when node ids repeat across buses)."""
        found = [
            ax
            for ax, spec in zip(self.axes, self.specs, strict=True)
            if spec.node_id == node_id and bus in ("", self.bus_names[spec.bus])
        ]
        if len(found) == 1:
            return found[0]
        if not found:
            nodes = sorted(f"{self.bus_names[s.bus]}:{s.node_id}" for s in self.specs)
            raise ValueError(
                f"no drive with node id {node_id}{f' on {bus}' if bus else ''} (nodes: {', '.join(nodes)})"
            )
        raise ValueError(f"node id {node_id} is on several buses: name the bus")

    def inject(self, fault: str, node_id: int, bus: str = "") -> None:
        """Fault injection: overcurrent / following_error (EMCY, fault reaction), heartbeat_silence
        (no more heartbeats), node_silence (nothing at all), sto (its Safe Torque Off input active:
        Enable Operation refused, the drive stays SWITCHED ON), clear (silences and STO end)."""
        axis = self.axis_of(node_id, bus)
        with self.lock:
            if fault == "overcurrent":
                axis.fault(EMCY_OVERCURRENT, ERR_REG_CURRENT)
            elif fault == "following_error":
                axis.fault(EMCY_FOLLOWING_ERROR)
            elif fault == "heartbeat_silence":
                axis.node.heartbeat_silent = True
            elif fault == "node_silence":
                axis.node.silent = True
            elif fault == "sto":
                axis.sto = True
            elif fault == "clear":
                axis.node.silent = axis.node.heartbeat_silent = False
                axis.sto = False
            else:
                raise ValueError(f"unknown fault {fault!r} (faults: {', '.join(FAULTS)})")
            self._send_queued()
        log.info("node %d: %s injected", node_id, fault)
