"""N simulated CiA 402 drives on one bus, moving one simulated arm.

`DriveSimulator.run()` is the drives' side of the bus in one loop: every frame is handed to
the nodes, a SYNC runs every drive's cycle (synchronous RPDOs applied, references to the arm,
actual values sampled, TPDOs sent), and the arm integrates on the wall clock in between, so it
keeps moving (or falls, braked) whatever the bus does. Faults are injected with `inject`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import can

from orccadd.config.robot import RobotConfig
from orccadd.drivesim.axis import EMCY_FOLLOWING_ERROR, EMCY_OVERCURRENT, ERR_REG_CURRENT, Axis, AxisUnits
from orccadd.drivesim.plant import DriveTrainArm
from orccadd.drivesim.slave import COB_SYNC, SlaveNode
from orccadd.model import RobotModel

FAULTS = ("overcurrent", "following_error", "heartbeat_silence", "node_silence", "clear")


@dataclass(frozen=True)
class AxisSpec:
    node_id: int
    eds: str
    units: AxisUnits


class DriveSimulator:
    def __init__(self, cfg: RobotConfig, axes: list[AxisSpec], bus: can.BusABC) -> None:
        if len(axes) != cfg.dof:
            raise ValueError(f"{len(axes)} drives for a {cfg.dof}-joint arm")
        self.cfg = cfg
        self.bus = bus
        self.arm = DriveTrainArm(cfg, RobotModel.from_config(cfg))
        self.lock = threading.Lock()  # held while frames, SYNCs, timers or injections run
        self.nodes = [SlaveNode(a.node_id, a.eds, self._send) for a in axes]
        self.axes = [
            Axis(node, j, self.arm, a.units) for j, (node, a) in enumerate(zip(self.nodes, axes, strict=True))
        ]
        self.by_id = {a.node_id: ax for a, ax in zip(axes, self.axes, strict=True)}
        self.syncs = 0
        self._last_sync_s: float | None = None
        self.period_s = cfg.control_period_s
        self.bus_error = ""

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
        except (can.CanError, OSError) as e:  # the bus is gone: the drives' own watchdogs act
            self.bus_error = str(e)

    def boot(self) -> None:
        now = time.monotonic()
        with self.lock:
            self.arm.step_to(now)
            for node, axis in zip(self.nodes, self.axes, strict=True):
                node.boot(now)
                axis.boot()

    def run(self, stop: Callable[[], bool], poll_s: float = 0.005) -> None:
        """Serve the bus until `stop()` (checked at least every `poll_s`; frames wake it at once,
        and the arm is integrated up to each frame's arrival)."""
        self.boot()
        while not stop():
            try:
                msg = self.bus.recv(poll_s)
            except (can.CanError, OSError) as e:
                self.bus_error = str(e)
                msg = None
                time.sleep(poll_s)
            now = time.monotonic()
            with self.lock:
                self.arm.step_to(now)
                if msg is not None:
                    if msg.arbitration_id == COB_SYNC and not msg.is_extended_id:
                        self._sync(now)
                    else:
                        for node in self.nodes:
                            node.on_frame(msg, now)
                for node in self.nodes:
                    node.poll(now)

    def _sync(self, now_s: float) -> None:
        if self._last_sync_s is not None:
            self.period_s = min(max(now_s - self._last_sync_s, 1e-4), 0.1)
        self._last_sync_s = now_s
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
