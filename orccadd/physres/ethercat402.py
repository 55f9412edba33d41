"""`ethercat402` backend: an arm of CiA 402 drives on an EtherCAT line (CoE), through SOEM.

The resource maps the Physical Resource contract onto the drives (`drivers.ethercat.master`):

- configure: the line opened and checked, each drive's process data mapped over SDO, the
  distributed clocks, SAFE-OP (`EcatMaster.start`); then the cyclic exchange, OP, and every
  drive walked to SWITCHED ON (powered, torque off, brake on). From there until the control
  loop's first tick a keeper thread runs the exchange every period (a slave in OP without
  outputs for its SM watchdog's time leaves OP, and its drive faults): the first tick takes it
  over for good, so a stalled loop is one the drives notice;
- activate(mode): the mode (0x6060 is in the RxPDO), then Enable Operation from the next ticks,
  holding where the arm is (reads say TORQUE_OFF until every drive is enabled);
- the clock: with distributed clocks the ticks are released at the reference clock's period
  starts (`wait_for_cycle`: each frame brings the reference time back, which maps it onto
  CLOCK_MONOTONIC), SYNC0 coming `sync0_shift_us` later; without, by the loop's own deadlines;
- read: the frame sent at the end of the last tick, back (no waiting: it has had a period):
  positions and velocities as the drives measure them, torques per mille through the gear; a
  drive's FAULT with its error code (0x603F, in the same frame) is FAULT; `lost_frames` frames in
  a row lost or short of the expected working counter is COMM_LOST naming where the line stops;
- write: each drive's outputs (the active mode's target from the command, the others holding)
  and the next frame;
- mode switch: the mode byte of the next frame, within one cycle (CSP and CST both mapped);
- safe_stop: quick stop on every drive (each ramps down at its quick-stop deceleration and
  switches off); STOPPED once every drive is off;
- reset_fault: slaves that left OP (the SM watchdog, a cable pulled and put back) taken back to
  OP, acknowledging their error; then fault reset (rising edge of bit 7) and Enable Operation.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.capabilities import object_dictionary
from orccadd.drivers.ethercat.pdo import layout_for
from orccadd.drivers.ethercat.settings import TARGET_OF_MODE, EthercatSettings, load_ethercat_settings
from orccadd.errors import ResourceError
from orccadd.fault import FaultKind
from orccadd.model import RobotModel
from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import MEASURED, ClockSource, Quantity, ResourceDescription, Source
from orccadd.runtime.clock import WallClock
from orccadd.state import FloatArray, JointState
from orccadd.types import CommandMode, Status

log = logging.getLogger("orccadd.ethercat")

MODE_OF = {
    CommandMode.POSITION: cia402.MODE_CSP,
    CommandMode.VELOCITY: cia402.MODE_CSV,
    CommandMode.TORQUE: cia402.MODE_CST,
}
COMMAND_OF = {v: k for k, v in MODE_OF.items()}
MAILBOX_POLL_S = 0.05
COMMAND_OF_MODE = {"csp": CommandMode.POSITION, "csv": CommandMode.VELOCITY, "cst": CommandMode.TORQUE}


def mapped_modes(s: EthercatSettings) -> frozenset[CommandMode]:
    layouts = [layout_for(object_dictionary(eds, 1)) for eds in s.eds_paths]
    return frozenset(
        COMMAND_OF_MODE[name]
        for name, index in TARGET_OF_MODE.items()
        if all(index in lay.rx for lay in layouts)
    )


class Ethercat402Arm(PhysicalResource):
    Settings = EthercatSettings

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        s: EthercatSettings = config.backend_settings
        return (f"EtherCAT line on {s.interface}",)

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        """Every mode whose target every drive's RxPDO carries (from their descriptions): with the
        mode of operation in the RxPDO too, the drives switch while enabled, within one cycle."""
        s: EthercatSettings = config.backend_settings
        return ResourceDescription(
            backend="ethercat402",
            joints=config.joint_names,
            modes=mapped_modes(s),
            mode_switch_needs_disable=False,
            position=MEASURED,
            velocity=MEASURED,  # the drive's velocity actual value (0x606C)
            torque=Quantity(Source.ESTIMATED, "the drive's torque actual value 0x6077, from motor current"),
            brakes=True,
            stop_categories=frozenset({0, 1, 2}),
            read_time_s=0.0,  # the frame sent at the end of the last tick is back: no waiting
            write_time_s=0.0,
            # with distributed clocks the reference clock's periods release the ticks
            clock=ClockSource.DEVICE if s.distributed_clocks else ClockSource.LOOP,
            device_period_s=config.control_period_s if s.distributed_clocks else 0.0,
            fault_reset=True,
        )

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> EthercatSettings:
        return load_ethercat_settings(raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        from orccadd.drivers.ethercat.master import EcatMaster  # pysoem: the `ethercat` extra

        s: EthercatSettings = config.backend_settings
        self.settings = s
        self.master = EcatMaster(
            s, list(config.joint_names), config.control_period_s, config.safe_stop.deceleration_rad_s2
        )
        n = self.dof
        self._pos = np.zeros(n)
        self._vel = np.zeros(n)
        self._tau = np.zeros(n)
        self._walk_to: cia402.State | None = None
        self._walk_t0 = 0.0
        self._walk_failed = ""
        self._fault_reset = False
        self._stop_t0 = 0.0
        self._comm_lost = False
        self._data = model.new_data()
        self._exchange = threading.RLock()  # one cycle at a time: the keeper's or a tick's
        self._loop_took_over = False
        self._keeper: threading.Thread | None = None
        self._mailbox: threading.Thread | None = None
        self._closing = threading.Event()
        self._sleeper = WallClock()

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        for w in self.master.start():
            log.warning("%s: %s", self.name, w)
        self.supported_modes = frozenset(COMMAND_OF[m] for m in self.master.modes())
        self._wait(self.master.step_operational, "OP on every slave", every=10)
        self._walk(cia402.State.SWITCHED_ON)
        self._wait(lambda: self._walk_to is None, "SWITCHED ON on every drive")
        self._keeper = threading.Thread(target=self._keep, name=f"{self.name}-ecat-keeper", daemon=True)
        self._keeper.start()
        self._mailbox = threading.Thread(
            target=self._watch_mailboxes, name=f"{self.name}-ecat-mailbox", daemon=True
        )
        self._mailbox.start()

    def _on_activate(self, mode: CommandMode) -> None:
        self.master.set_mode(MODE_OF[mode])
        self._hold_here()
        self._walk(cia402.State.OPERATION_ENABLED)

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        self.master.set_mode(MODE_OF[mode])

    def _on_deactivate(self) -> None:
        self._walk_to = None
        self.master.set_controlword(cia402.CW_SHUTDOWN)  # power stage off, still ready
        self._pump(0.1)

    def _on_shutdown(self) -> None:
        self._closing.set()
        for thread in (self._keeper, self._mailbox):
            if thread is not None:
                thread.join(1.0)
        with self._exchange:
            self.master.close()

    def _on_clear_stop(self) -> None:
        self._enable_blocking()

    def _on_reset_fault(self) -> None:
        """Slaves back to OP where they left it, then fault reset (the next cycles' rising edges)."""
        self._wait(self.master.step_operational, "OP on every slave", every=10)
        self.master.forget_emergencies()
        self._fault_reset = True
        self._walk_failed = ""
        self.fault = None

    # ---- without a loop: the keeper and the blocking phases --------------------------------------
    def _keep(self) -> None:
        """The cyclic exchange from configure until the loop's first tick (see the module's doc)."""
        period = self.config.control_period_s
        while not self._closing.is_set() and not self._loop_took_over:
            if not self.loop_ticking:
                self._cycle_without_loop()
            else:
                time.sleep(period)

    def _watch_mailboxes(self) -> None:
        """A drive's CoE emergency, read from its mailbox once its statusword shows the fault
        (the fault is reported from the process data in that tick; the emergency adds its error
        register to the words)."""
        while not self._closing.wait(MAILBOX_POLL_S):  # SOEM takes frames from two threads
            self.master.read_emergencies()

    def _cycle_without_loop(self) -> None:
        with self._exchange:
            if self.master.m is not None:
                now = time.monotonic()
                self._read_into(now, self.state, loop=False)
                self._on_keep_alive(now)
        time.sleep(self.config.control_period_s)

    def _pump(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if self.loop_ticking:
                time.sleep(self.config.control_period_s)
            else:
                self._cycle_without_loop()

    def _wait(self, done: Callable[[], bool], what: str, every: int = 1) -> None:
        """Cycle (or let the ticks cycle) until `done()`, asked every `every` cycles."""
        end = time.monotonic() + self.settings.state_timeout_s
        n = 0
        while True:
            if n % every == 0 and done():
                return
            n += 1
            if time.monotonic() > end:
                states = ", ".join(
                    f"{d.where}: {d.state.name}, statusword 0x{d.statusword:04X}" for d in self.master.drives
                )
                raise ResourceError(
                    f"resource {self.name!r}: no {what} within {self.settings.state_timeout_s:g} s "
                    f"(state_timeout_s; drives {states})"
                )
            if self.loop_ticking:
                time.sleep(self.config.control_period_s)
            else:
                self._cycle_without_loop()

    def _walk(self, target: cia402.State) -> None:
        self._walk_t0 = time.monotonic()
        self._walk_to = target

    def _step_walk(self, target: cia402.State) -> None:
        m = self.master
        if target is cia402.State.OPERATION_ENABLED:
            q = self.state.q_rad
            for j, d in enumerate(m.drives):  # enabled holding where it is, as measured now
                if d.state is not cia402.State.OPERATION_ENABLED:
                    self._pos[j] = q[j]
                    self._vel[j] = 0.0
        if m.step_towards(target):
            self._walk_to = None
        elif time.monotonic() - self._walk_t0 > self.settings.state_timeout_s:
            late = next(d for d in m.drives if d.state is not target)
            self._walk_failed = (
                f"{late.where} did not reach {target.name} within {self.settings.state_timeout_s:g} s "
                f"(state_timeout_s): statusword 0x{late.statusword:04X} ({late.state.name}), controlword "
                f"0x{late.controlword:04X}"
            )
            self._walk_to = None

    def _enable_blocking(self) -> None:
        self._hold_here()
        self._walk(cia402.State.OPERATION_ENABLED)
        try:
            self._wait(lambda: self._walk_to is None, "OPERATION ENABLED on every drive")
        finally:
            self._walk_to = None
        self.master.set_controlword(cia402.CW_ENABLE_OPERATION)
        self._hold_here()

    def _hold_here(self) -> None:
        q = self.state.q_rad
        self._pos[:] = q
        self._vel[:] = 0.0
        self._tau[:] = pin.computeGeneralizedGravity(self.model.model, self._data, q)

    def wait_for_cycle(self, timeout_s: float) -> int:
        """With distributed clocks: the next period's start on the reference clock (mapped to
        ours by each frame's reference time), or -1 after `timeout_s`."""
        now = time.monotonic_ns()
        due = self.master.next_cycle_ns(now)
        if due - now > timeout_s * 1e9:
            self._sleeper.sleep_until_ns(now + int(timeout_s * 1e9))
            return -1
        self._sleeper.sleep_until_ns(due)
        return due

    # ---- tick hooks ---------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState, loop: bool = True) -> int:
        if loop and not self._loop_took_over:
            self._loop_took_over = True  # the keeper stops: from now on a stalled loop shows
        with self._exchange:
            rep = self.master.receive()
        flags = 0
        powered = True
        for j, d in enumerate(self.master.drives):
            state.q_rad[j] = d.position_counts / d.counts_per_rad
            state.dq_rad_s[j] = d.velocity_counts / d.counts_per_rad
            state.tau_nm[j] = d.torque_per_mille * d.nm_per_mille
            powered = powered and d.state in cia402.POWERED
        if rep.comm_lost:
            flags |= Status.COMM_LOST
            self._set_fault(FaultKind.COMM_LOST, rep.comm_lost, rep.comm_lost_joint)
        elif rep.fault:
            flags |= Status.FAULT
            self._set_fault(FaultKind.DEVICE, rep.fault, rep.fault_joint, rep.fault_code)
            state.fault_code = rep.fault_code
        elif self._walk_failed:
            flags |= Status.FAULT
            self._set_fault(FaultKind.DEVICE, self._walk_failed)
        if not powered:
            flags |= Status.TORQUE_OFF
        self._comm_lost = bool(rep.comm_lost)
        return flags

    def _send(self) -> None:
        with self._exchange:
            self.master.transmit(self._pos, self._vel, self._tau)

    def _on_keep_alive(self, t_s: float) -> None:
        m = self.master
        walk_to = self._walk_to
        if self._fault_reset:
            self._fault_reset = not m.step_fault_reset()
        elif walk_to is not None:
            self._step_walk(walk_to)
        elif self._stop_flags & Status.STOPPING:
            off = m.step_quick_stop()
            timed_out = t_s - self._stop_t0 > self.config.safe_stop.timeout_s
            if off or (self._comm_lost and timed_out):  # unreachable drives stop on their own watchdogs
                self._mark_stopped(torque_off=True)
        self._send()

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        if self._walk_to is not None:
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
        self._send()
        return 0

    def _begin_safe_stop(self) -> None:
        self._walk_to = None
        self._stop_t0 = self.state.t_s
        self._pos[:] = self.state.q_rad
        self._vel[:] = 0.0
        self.master.step_quick_stop()
        self._send()

    def _details(self) -> dict[str, Any]:
        m = self.master
        return {
            "interface": self.settings.interface,
            "frames": m.frames,
            "frames_lost": m.frames_lost,
            "wkc_errors": m.wkc_errors,
            "expected_wkc": m.expected_wkc,
            "last_wkc": m.last_wkc,
            "dc_time_ns": m.dc_time_ns,
            **{f"slave_{d.position}": d.identity for d in m.drives},
            **{f"emergency_{d.position}": d.emergency for d in m.drives if d.emergency},
        }
