"""N simulated CiA 402 drives on one bus, moving one simulated arm.

`DriveSimulator.run()` is the drives' side of the bus in one loop: every frame is handed to
the nodes, a SYNC runs every drive's cycle (synchronous RPDOs applied, references to the arm,
actual values sampled, TPDOs sent), and the arm integrates on the wall clock in between, so it
keeps moving (or falls, braked) whatever the bus does. Faults are injected with `inject`. The
drives are as strict as real ones (`Strictness`: heartbeat consumer, COB-ID valid bit, a mode
display that lags) unless told otherwise.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
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

FAULTS = ("overcurrent", "following_error", "heartbeat_silence", "node_silence", "clear")


@dataclass(frozen=True)
class AxisSpec:
    node_id: int
    eds: str
    units: AxisUnits


class DriveSimulator:
    def __init__(
        self, cfg: RobotConfig, axes: list[AxisSpec], bus: can.BusABC, strict: Strictness = STRICT
    ) -> None:
        if len(axes) != cfg.dof:
            raise ValueError(f"{len(axes)} drives for a {cfg.dof}-joint arm")
        self.cfg = cfg
        self.bus = bus
        self.strict = strict
        self.arm = DriveTrainArm(cfg, RobotModel.from_config(cfg))
        self.lock = threading.Lock()  # held while frames, SYNCs, timers or injections run
        self.nodes = [SlaveNode(a.node_id, a.eds, self._send, strict.cob_id_valid_bit) for a in axes]
        self.axes = [
            Axis(node, j, self.arm, a.units, strict)
            for j, (node, a) in enumerate(zip(self.nodes, axes, strict=True))
        ]
        self.by_id = {a.node_id: ax for a, ax in zip(axes, self.axes, strict=True)}
        self.syncs = 0
        self.period_s = cfg.control_period_s  # the drives' cycle when their dictionary has none
        self.bus_error = ""
        self._errors_logged: set[str] = set()
        # how long frames waited between the bus and this loop (the hub stamps each frame with
        # the wall clock as it forwards it): a drive on a real bus reads its frames within µs
        self.frame_age_s: deque[float] = deque(maxlen=10_000)
        self._routes: dict[int, list[SlaveNode]] = {}  # COB-ID -> the nodes that consume it
        self._routes_generation = -1
        self.longest_gap_s = 0.0  # longest time between two passes of the loop once SYNCs flow

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
        except (can.CanError, OSError) as e:  # the bus is gone: the drives' own watchdogs act
            self._bus_failed(e)

    def _send_queued(self) -> None:
        """Hand frames queued by a batching bus (`QueuedSocketcandBus`) to the bus, in order."""
        send_queued = getattr(self.bus, "send_queued", None)
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
        batch: list[can.Message] = []
        last = time.monotonic()
        while not stop():
            t = time.monotonic()
            if self.syncs:  # (before, resets of whole dictionaries take their time)
                self.longest_gap_s = max(self.longest_gap_s, t - last)
            last = t
            batch.clear()
            try:
                msg = self.bus.recv(poll_s)
                while msg is not None:
                    batch.append(msg)
                    msg = self.bus.recv(0.0)
            except (can.CanError, OSError) as e:
                self._bus_failed(e)
                time.sleep(poll_s)
            now = time.monotonic()
            wall = time.time()
            for msg in batch:
                if msg.timestamp:
                    self.frame_age_s.append(wall - msg.timestamp)
            with self.lock:
                self.arm.step_to(now)
                for msg in batch:
                    self._dispatch(msg, now)
                for node, axis in zip(self.nodes, self.axes, strict=True):
                    node.poll(now)
                    axis.poll(now)
                self._send_queued()

    def _dispatch(self, msg: can.Message, now_s: float) -> None:
        cob = msg.arbitration_id
        if msg.is_extended_id:
            return
        if cob == COB_SYNC:
            self._sync(now_s)
            return
        generation = sum(node.pdo_generation for node in self.nodes)
        if generation != self._routes_generation:
            self._routes = {}
            for node in self.nodes:  # descriptions may give several nodes one COB-ID (e35's)
                for c in node.unicast_cobs():
                    self._routes.setdefault(c, []).append(node)
            self._routes_generation = generation
        for node in self._routes.get(cob, self.nodes):
            node.on_frame(msg, now_s)

    def _sync(self, now_s: float) -> None:
        self.syncs += 1
        for node in self.nodes:
            node.on_sync(now_s)
        for axis in self.axes:
            axis.cycle(now_s, self.period_s)
        for node in self.nodes:
            node.transmit_sync_pdos()

    def inject(self, node_id: int, fault: str) -> None:
        """Fault injection: overcurrent / following_error (EMCY, fault reaction), heartbeat_silence
        (no more heartbeats), node_silence (nothing at all), clear (silences end)."""
        axis = self.by_id.get(node_id)
        if axis is None:
            raise ValueError(f"no drive with node id {node_id} (nodes: {sorted(self.by_id)})")
        with self.lock:
            if fault == "overcurrent":
                axis.fault(EMCY_OVERCURRENT, ERR_REG_CURRENT)
            elif fault == "following_error":
                axis.fault(EMCY_FOLLOWING_ERROR)
            elif fault == "heartbeat_silence":
                axis.node.heartbeat_silent = True
            elif fault == "node_silence":
                axis.node.silent = True
            elif fault == "clear":
                axis.node.silent = axis.node.heartbeat_silent = False
            else:
                raise ValueError(f"unknown fault {fault!r} (faults: {', '.join(FAULTS)})")
            self._send_queued()
        log.info("node %d: %s injected", node_id, fault)
