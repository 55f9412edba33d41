"""N simulated EtherCAT CiA 402 drives on one line, moving one simulated arm.

`EcatSimulator.run(link, stop)` is the slaves' side of the wire in one loop: between frames the
arm integrates on the clock and every drive runs its time (SYNC0 pulses, free-run cycles, the SM
watchdog); a frame is answered as the chain of ESCs would (`chain.Chain`) at the time it reached
the link (the kernel's time stamp: its distributed-clock latches and the system time it carries
are the wire's, not this loop's), after whatever was due before then. Faults are injected with
`inject`: a drive's (overcurrent, following_error, sto, clear, power_cycle) or the wire's
(unplug, replug, lose_frames, short_wkc).
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from orccadd.config.robot import RobotConfig
from orccadd.drivesim.axis import EMCY_FOLLOWING_ERROR, EMCY_OVERCURRENT, ERR_REG_CURRENT
from orccadd.drivesim.plant import DriveTrainArm
from orccadd.ecatsim.chain import Chain
from orccadd.ecatsim.drive import DriveSlave, DriveSpec
from orccadd.ecatsim.frame import EthernetFrame, FrameError
from orccadd.ecatsim.registers import AlStatusCode
from orccadd.model import RobotModel
from orccadd.runtime import sim_control

log = logging.getLogger("orccadd.ecatsim")

DRIVE_FAULTS = ("overcurrent", "following_error", "sto", "clear", "power_cycle", "al_error")
WIRE_FAULTS = ("unplug", "replug", "lose_frames", "short_wkc")
IDLE_WAKE_S = 0.0005  # the drives' own time runs at least this often


class Wire(Protocol):
    def fileno(self) -> int: ...
    def receive(self) -> tuple[bytes, int] | None: ...  # a frame and when it arrived (monotonic ns)
    def send(self, frame: bytes) -> None: ...


class EcatSimulator:
    def __init__(self, cfg: RobotConfig, drives: list[DriveSpec]) -> None:
        if len(drives) != cfg.dof:
            raise ValueError(f"{len(drives)} drives for a {cfg.dof}-joint arm")
        self.arm = DriveTrainArm(cfg, RobotModel.from_config(cfg))
        self.slaves = [DriveSlave(k + 1, spec, self.arm) for k, spec in enumerate(drives)]
        self.chain = Chain([s.esc for s in self.slaves])
        self.lock = threading.Lock()  # held while frames, the drives' time or injections run
        self.bad_frames = 0
        self.longest_gap_s = 0.0
        self._advanced_ns = 0

    # ---- the wire ---------------------------------------------------------------------------
    def answer(self, raw: bytes, clock_ns: int) -> bytes | None:
        """The frame that goes back to the master (None: lost, or not EtherCAT)."""
        try:
            frame = EthernetFrame.parse(raw)
        except FrameError as e:
            self.bad_frames += 1
            if self.bad_frames <= 10:
                log.warning("frame refused: %s", e)
            return None
        out = self.chain.process(frame.datagrams, clock_ns)
        if out is None:
            return None
        # an ESC's port 0 sets the locally administered bit of the source address on the way back
        source = bytes([frame.source[0] | 0x02]) + frame.source[1:]
        return EthernetFrame(frame.destination, source, out).encode()

    def advance(self, clock_ns: int) -> None:
        """The world up to `clock_ns`: the arm integrated, each drive's time run."""
        self._advanced_ns = clock_ns
        self.arm.step_to(clock_ns * 1e-9)
        for slave in self.slaves:
            slave.tick(clock_ns)

    def run(self, wire: Wire, stop: Callable[[], bool]) -> None:
        last = time.monotonic()
        while not stop():
            select.select([wire], [], [], IDLE_WAKE_S)
            now = time.monotonic()
            self.longest_gap_s = max(self.longest_gap_s, now - last)
            last = now
            with self.lock:
                got = wire.receive()
                while got is not None:
                    raw, arrived_ns = got
                    # the world as it was when the frame reached the line (a SYNC0 before it ran
                    # before it, one after it after), then the frame, as ESCs serve it on the wire
                    self.advance(max(arrived_ns, self._advanced_ns))
                    reply = self.answer(raw, arrived_ns)
                    if reply is not None:
                        wire.send(reply)
                    got = wire.receive()
                self.advance(time.monotonic_ns())

    # ---- faults and status ------------------------------------------------------------------
    def inject(self, req: sim_control.Injection) -> None:
        with self.lock:
            self._inject(req)
        log.info("%s injected%s", req.fault, f" on slave {req.device}" if req.device else "")

    def _inject(self, req: sim_control.Injection) -> None:
        fault, params = req.fault, req.params
        if fault in WIRE_FAULTS:
            if fault == "unplug":
                self.chain.unplug(self._position(req))
            elif fault == "replug":
                self.chain.replug()
            elif fault == "lose_frames":
                self.chain.lose_frames(int(params.get("frames", 1)))
            else:
                self.chain.leave_process_data(self._position(req), int(params.get("frames", 1)))
            return
        if fault not in DRIVE_FAULTS:
            raise ValueError(f"unknown fault {fault!r} (faults: {', '.join(DRIVE_FAULTS + WIRE_FAULTS)})")
        slave = self.slaves[self._position(req) - 1]
        axis = slave.axis
        if fault == "overcurrent":
            axis.fault(EMCY_OVERCURRENT, ERR_REG_CURRENT)
        elif fault == "following_error":
            axis.fault(EMCY_FOLLOWING_ERROR)
        elif fault == "sto":
            axis.sto = True
        elif fault == "clear":
            axis.sto = False
        elif fault == "al_error":  # the slave's own error: SAFE-OP + ERROR with this AL status code
            slave.leave_op(int(params.get("code", AlStatusCode.SYNCHRONIZATION_ERROR)))
        else:
            slave.power_cycle()

    def _position(self, req: sim_control.Injection) -> int:
        if req.device is None or not 1 <= req.device <= len(self.slaves):
            raise ValueError(
                f'this fault names its slave: "device": 1-{len(self.slaves)} (its place on the line)'
            )
        return req.device

    def status(self) -> dict[str, Any]:
        with self.lock:
            c = self.chain.counters
            return {
                "q_rad": [float(x) for x in self.arm.q],
                "dq_rad_s": [float(x) for x in self.arm.dq],
                "devices": [
                    sim_control.device(s.position, s.axis.sm.state.name, s.axis.fault_text())
                    for s in self.slaves
                ],
                "al_states": [s.esc.al_state.name for s in self.slaves],
                "al_status_codes": [s.esc.al_status_code for s in self.slaves],
                "cycles": [s.cycles for s in self.slaves],
                "frames": c.frames,
                "frames_lost": c.frames_lost,
                "bad_frames": self.bad_frames,
                "reachable": len(self.chain.reachable),
                "longest_loop_gap_ms": self.longest_gap_s * 1e3,
            }
