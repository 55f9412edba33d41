"""What an arm of CiA 402 drives is as a Physical Resource, whatever bus carries the drives'
words (`canopen402`, `ethercat402`): the drives walked to a state by the cycles' controlwords
(SWITCHED ON at configure, OPERATION ENABLED holding where the arm is), quick stop as the safe
stop, fault reset, the targets of the three cyclic modes, and the status flags a cycle's report
becomes. A backend gives its drives (`drives`: each with `state`, `statusword`, `controlword`,
`where`), sends one cycle's outputs (`_send`), says when a walk may step (`_walk_ready`: CANopen
waits until every drive answered a SYNC) and how long a walk may take (`_walk_timeout_s`).

Blocking phases (configure, clear_stop, reset) leave the cycles to the control loop when it
ticks (`loop_ticking`) and run them themselves otherwise (`_cycle_without_loop`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.cia402 import CycleReport
from orccadd.errors import ResourceError
from orccadd.fault import FaultKind
from orccadd.model import RobotModel
from orccadd.physres.base import PhysicalResource
from orccadd.state import FloatArray
from orccadd.types import CommandMode, Status

MODE_OF = {
    CommandMode.POSITION: cia402.MODE_CSP,
    CommandMode.VELOCITY: cia402.MODE_CSV,
    CommandMode.TORQUE: cia402.MODE_CST,
}
COMMAND_OF = {v: k for k, v in MODE_OF.items()}


class Drive(cia402.DriveWords, Protocol):
    statusword: int

    @property
    def where(self) -> str: ...


class Cia402Arm(PhysicalResource):
    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        n = self.dof
        self._pos = np.zeros(n)  # the targets the next cycle sends
        self._vel = np.zeros(n)
        self._tau = np.zeros(n)
        self._walk_to: cia402.State | None = None  # where the cycles take the drives (None: nowhere)
        self._walk_t0 = 0.0  # when the walk under way began (monotonic s)
        self._walk_failed = ""  # why a walk ended without its state (a fault until `reset`)
        self._fault_reset = False
        self._stop_t0 = 0.0
        self._comm_lost = False
        self._data = model.new_data()

    # ---- what a backend gives ----------------------------------------------------------------
    @property
    def drives(self) -> Sequence[Drive]:
        raise NotImplementedError

    def _send(self, t_s: float) -> None:
        """One cycle's outputs: each drive's controlword and the targets `_pos`, `_vel`, `_tau`."""
        raise NotImplementedError

    def _walk_ready(self) -> bool:
        """Whether a walk may take its next step (every drive's state current)."""
        return True

    @property
    def _walk_timeout_s(self) -> float:
        raise NotImplementedError

    _walk_timeout_key = ""  # the setting it comes from, for the words of a timeout

    # ---- blocking phases ------------------------------------------------------------------------
    def _cycle_without_loop(self) -> None:
        now = time.monotonic()
        self._read_into(now, self.state)
        self._on_keep_alive(now)
        time.sleep(self.config.control_period_s)

    def _pump(self, seconds: float) -> None:
        """Cycles for `seconds`: the loop's where it ticks, ours otherwise."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if self.loop_ticking:
                time.sleep(self.config.control_period_s)
            else:
                self._cycle_without_loop()

    def _wait(self, done: Callable[[], bool], what: str, every: int = 1) -> None:
        """Cycle (or let the ticks cycle) until `done()`, asked every `every` cycles; a
        ResourceError naming each drive's state after `_walk_timeout_s`."""
        limit = self._walk_timeout_s
        end = time.monotonic() + limit
        n = 0
        while not (n % every == 0 and done()):
            n += 1
            if time.monotonic() > end:
                states = ", ".join(
                    f"{d.where}: {d.state.name}, statusword 0x{d.statusword:04X}" for d in self.drives
                )
                key = self._walk_timeout_key
                raise ResourceError(
                    f"resource {self.name!r}: no {what} within {limit:g} s ({key}; drives {states})"
                )
            if self.loop_ticking:  # asked at every step: a loop that stops is taken over
                time.sleep(self.config.control_period_s)
            else:
                self._cycle_without_loop()

    def _walk(self, target: cia402.State) -> None:
        """From the next cycle on, take every drive to `target`."""
        self._walk_t0 = time.monotonic()
        self._walk_to = target

    def _step_walk(self, target: cia402.State) -> None:
        if not self._walk_ready():
            return  # controlwords as they are until every drive's state is current
        drives = self.drives
        if target is cia402.State.OPERATION_ENABLED:
            q = self.state.q_rad
            for j, d in enumerate(drives):  # enabled holding where it is, as measured now
                if d.state is not cia402.State.OPERATION_ENABLED:
                    self._pos[j] = q[j]
                    self._vel[j] = 0.0
        if cia402.step_towards(drives, target):
            self._walk_to = None
        elif time.monotonic() - self._walk_t0 > self._walk_timeout_s:
            late = next(d for d in drives if d.state is not target)
            self._walk_failed = (
                f"{late.where} did not reach {target.name} within {self._walk_timeout_s:g} s "
                f"({self._walk_timeout_key}): statusword 0x{late.statusword:04X} ({late.state.name}), "
                f"controlword 0x{late.controlword:04X}"
            )
            self._walk_to = None  # commands stay unsent: the fault stops the arm

    def _enable_blocking(self) -> None:
        self._hold_here()
        self._walk(cia402.State.OPERATION_ENABLED)
        try:
            self._wait(lambda: self._walk_to is None, "OPERATION ENABLED on every drive")
        finally:
            self._walk_to = None
        for d in self.drives:
            d.controlword = cia402.CW_ENABLE_OPERATION
        self._hold_here()

    def _hold_here(self) -> None:
        """Targets that keep the arm where it is: its position, no speed, gravity torque."""
        q = self.state.q_rad
        self._pos[:] = q
        self._vel[:] = 0.0
        self._tau[:] = pin.computeGeneralizedGravity(self.model.model, self._data, q)

    # ---- lifecycle hooks -------------------------------------------------------------------------
    def _on_clear_stop(self) -> None:
        self._enable_blocking()

    # ---- tick hooks ------------------------------------------------------------------------------
    def _flags(self, rep: CycleReport, powered: bool) -> int:
        """A cycle's report as status flags (and the fault recorded)."""
        flags = 0
        if rep.comm_lost:
            flags |= Status.COMM_LOST
            self._set_fault(FaultKind.COMM_LOST, rep.comm_lost, rep.comm_lost_joint)
        elif rep.fault:
            flags |= Status.FAULT
            self._set_fault(FaultKind.DEVICE, rep.fault, rep.fault_joint, rep.fault_code)
            self.state.fault_code = rep.fault_code
        elif self._walk_failed:
            flags |= Status.FAULT
            self._set_fault(FaultKind.DEVICE, self._walk_failed)
        if not powered:
            flags |= Status.TORQUE_OFF
        self._comm_lost = bool(rep.comm_lost)
        return flags

    def _on_keep_alive(self, t_s: float) -> None:
        """No command this tick: the controlwords of the sequence under way (fault reset, a walk,
        quick stop) and targets that hold, so every drive still gets its cycle."""
        walk_to = self._walk_to
        if self._fault_reset:
            self._fault_reset = not cia402.step_fault_reset(self.drives)
        elif walk_to is not None:
            self._step_walk(walk_to)
        elif self._stop_flags & Status.STOPPING:
            off = cia402.step_quick_stop(self.drives)
            timed_out = t_s - self._stop_t0 > self.config.safe_stop.timeout_s
            if off or (self._comm_lost and timed_out):  # unreachable drives stop on their own watchdogs
                self._mark_stopped(torque_off=True)
        self._send(t_s)

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        if self._walk_to is not None:  # not enabled yet: hold, the command is not sent
            self._on_keep_alive(t_s)
            return 0
        st = self.state
        if mode is CommandMode.POSITION:
            self._pos[:] = command
            self._vel[:] = 0.0
            self._tau[:] = st.tau_nm
        elif mode is CommandMode.VELOCITY:
            self._vel[:] = command
            self._pos[:] = st.q_rad
            self._tau[:] = st.tau_nm
        else:
            self._tau[:] = command
            self._pos[:] = st.q_rad
            self._vel[:] = 0.0
        self._send(t_s)
        return 0

    def _begin_safe_stop(self) -> None:
        """Quick stop on every drive (each ramps down at its own deceleration and switches off)."""
        self._walk_to = None
        t_s = self.state.t_s  # the tick's time (safe_stop runs inside a tick, after read)
        self._stop_t0 = t_s
        self._pos[:] = self.state.q_rad
        self._vel[:] = 0.0
        cia402.step_quick_stop(self.drives)
        self._send(t_s)
