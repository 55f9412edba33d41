"""`canopen402` backend: an arm of CiA 402 drives on a CANopen bus (SocketCAN, or socketcand).

The resource maps the Physical Resource contract onto the drives (`drivers.canopen.master`):

- configure: the startup sequence (reset, boot-up, PDO mapping, heartbeats, mode), SYNC on, then
  every drive walked to SWITCHED ON (powered, torque off, brake on);
- activate(mode): the drives' mode (POSITION = CSP, VELOCITY = CSV, TORQUE = CST), shown by
  every drive (0x6061); Enable Operation is left to the first ticks of the loop, once SYNC runs
  and every drive answered it, holding where the arm is (until then reads say TORQUE_OFF and
  commands are not sent): the daemon's setup between activate and the loop's first tick leaves
  no enabled drive without SYNC, and our heartbeat runs through it (`CanopenMaster.start`);
- read: the frames of the last cycle (positions in increments and torques in per mille through
  the gear; velocity from successive positions), and the watchdogs: a drive fault (EMCY) is
  FAULT, a lost heartbeat, a silent node, a reboot or a dead bus is COMM_LOST, both type 3;
- write: the RPDOs, the active mode's target from the command and the other target holding;
- safe_stop: quick stop on every axis (each drive ramps down at its own quick-stop
  deceleration and switches off, option code 2); STOPPED once every drive is off;
- reset_fault / clear_stop: fault reset (rising edge of bit 7), then back to OPERATION ENABLED;
- switch_mode: 0x6060 by non-blocking SDO writes, answered within `sdo_timeout_s`.

On a tick without a command (the base class ignores commands while stopping, stopped or
re-enabling; a task waiting or faulted sends none) `keep_alive` sends the RPDOs, so the drives
always get their controlword and a target that holds the position.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.capabilities import MODE_CODES
from orccadd.drivers.canopen.master import POWERED, CanopenMaster
from orccadd.drivers.canopen.settings import CanopenSettings, load_canopen_settings
from orccadd.drivers.canopen.startup import mode_not_shown
from orccadd.errors import ResourceError
from orccadd.model import RobotModel
from orccadd.physres.cia402_arm import COMMAND_OF, MODE_OF, Cia402Arm, Drive
from orccadd.physres.description import MEASURED, Quantity, ResourceDescription, Source
from orccadd.runtime.rt import ThreadsStartedHere
from orccadd.state import JointState
from orccadd.types import CommandMode

VELOCITY_FILTER = 0.5  # first-order filter weight of the newest position difference


class Canopen402Arm(Cia402Arm):
    Settings = CanopenSettings

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        """Each drive's node id on its bus (two resources may share a bus, not a node), and the
        bus's SYNC and heartbeat, which one master produces: the bus itself."""
        s: CanopenSettings = config.backend_settings
        buses = s.bus_list()
        out = [f"CAN bus {b.where()} (its SYNC producer)" for b in buses]
        for b in buses:
            out.extend(f"CAN node {s.axes[i].node_id} on {b.where()}" for i in b.axes)
        return tuple(out)

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        """The configured mode and its partner (CSP with CST): the RPDO carries both targets,
        so the drives switch between them while enabled. The set narrows at configure, to what
        every drive's description and mapping allow."""
        s: CanopenSettings = config.backend_settings
        first = COMMAND_OF[MODE_CODES[s.mode]]
        partner = CommandMode.POSITION if first is CommandMode.TORQUE else CommandMode.TORQUE
        return ResourceDescription(
            backend="canopen402",
            joints=config.joint_names,
            modes=frozenset({first, partner}),
            mode_switch_needs_disable=False,
            position=MEASURED,
            velocity=Quantity(Source.ESTIMATED, "position differences over the drives' SYNC times"),
            torque=Quantity(Source.ESTIMATED, "the drive's torque actual value 0x6077, from motor current"),
            brakes=True,
            stop_categories=frozenset({0, 1, 2}),
            # reads drain what arrived and writes queue frames, neither waits on the bus; whether
            # the bus carries a cycle's frames in a period is the settings' bus-load check
            read_time_s=0.0,
            write_time_s=0.0,
            fault_reset=True,
        )

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> CanopenSettings:
        return load_canopen_settings(raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        s: CanopenSettings = config.backend_settings
        self.settings = s
        self.master = CanopenMaster(s, list(config.joint_names), config.control_period_s)
        self._walk_after: list[int] = []  # each drive's TPDO count when the walk began
        self._pumping = False  # a cycle run by this resource, not by the control loop

    @property
    def drives(self) -> Sequence[Drive]:
        return self.master.axes

    @property
    def _walk_timeout_s(self) -> float:
        return self.settings.startup_timeout_s

    _walk_timeout_key = "startup_timeout_s"

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        with ThreadsStartedHere(self.master.s.io_priority) as started:  # the buses' I/O threads
            warnings = self.master.start()
        for w in [*warnings, *started.warnings]:
            logging.getLogger("orccadd.canopen").warning("%s: %s", self.name, w)
        modes = frozenset.intersection(*(a.modes for a in self.master.axes))
        self.supported_modes = frozenset(COMMAND_OF[m] for m in modes)
        self._walk(cia402.State.SWITCHED_ON)
        self._wait(lambda: self._walk_to is None, "SWITCHED ON on every drive")

    def _on_activate(self, mode: CommandMode) -> None:
        """The mode, then Enable Operation from the loop's first ticks (see the module's doc)."""
        self._set_mode_blocking(mode)
        self._hold_here()
        self._walk(cia402.State.OPERATION_ENABLED)

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        self.master.write_mode(MODE_OF[mode])

    def _on_deactivate(self) -> None:
        self._walk_to = None
        self.master.set_controlword(cia402.CW_SHUTDOWN)  # power stage off, still ready
        self._pump(0.1)

    def _on_shutdown(self) -> None:
        self.master.close()

    def _on_reset_fault(self) -> None:
        """Fault reset on every faulted drive: the next cycles send the rising edges."""
        self.master.clear_faults()
        self._fault_reset = True
        self._walk_failed = ""
        self.fault = None

    # ---- helpers for the blocking phases (the loop may or may not be ticking) -------------
    def _cycle_without_loop(self) -> None:
        self._pumping = True  # not the loop's: our heartbeat stays the startup producer's
        try:
            super()._cycle_without_loop()
        finally:
            self._pumping = False

    def _set_mode_blocking(self, mode: CommandMode) -> None:
        """0x6060 on every drive, then 0x6061 read until every drive shows the mode."""
        code = MODE_OF[mode]
        m = self.master
        if all(a.mode_code == code and a.mode_shown == code and a.sdo_pending is None for a in m.axes):
            return
        m.write_mode(code)
        self._await_sdo_answers(f"answer to the mode change ({mode.name.lower()})")
        timeout_s = self.settings.mode_display_timeout_s
        end = time.monotonic() + timeout_s
        while True:
            m.request_mode_display()
            self._await_sdo_answers("modes of operation display (0x6061)")
            late = [a for a in m.axes if a.mode_shown != code]
            if not late:
                return
            if time.monotonic() > end:
                a = late[0]
                error = mode_not_shown(f"node {a.node_id} ({a.name})", code, a.mode_shown, timeout_s)
                raise ResourceError(f"resource {self.name!r}: {error}")

    def _await_sdo_answers(self, what: str) -> None:
        self._wait(lambda: all(a.sdo_pending is None for a in self.master.axes), what)
        errors = [a.sdo_error for a in self.master.axes if a.sdo_error]
        if errors:
            raise ResourceError(f"resource {self.name!r}: {errors[0]}")

    def _walk(self, target: cia402.State) -> None:
        """From the next tick on, take every drive to `target`, once each answered a SYNC since
        now (a fresh TPDO: its state is current and the cyclic exchange runs)."""
        self._walk_after = [a.tpdo_count for a in self.master.axes]
        super()._walk(target)

    def _walk_ready(self) -> bool:
        return all(a.tpdo_count > n for a, n in zip(self.master.axes, self._walk_after, strict=True))

    # ---- tick hooks -------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState) -> int:
        m = self.master
        if not self._pumping:
            m.loop_started()  # our heartbeat from the loop's ticks on
        rep = m.receive(t_s)
        powered = True
        for j, a in enumerate(m.axes):
            state.q_rad[j] = a.position_counts / a.counts_per_rad
            if a.fresh:  # velocity over the drive's own sampling interval, not our tick's
                a.fresh = False
                # the drive samples at SYNC, and SYNCs are at least a period apart; frames can
                # reach us closer together (in a burst after a stall of the bus): never less
                dt = max(a.position_time_s - a.prev_position_time_s, self.config.control_period_s)
                if a.prev_position_time_s and dt < 0.5:
                    dq = (a.position_counts - a.prev_position_counts) / a.counts_per_rad / dt
                    state.dq_rad_s[j] += VELOCITY_FILTER * (dq - state.dq_rad_s[j])
            state.tau_nm[j] = a.torque_per_mille * a.nm_per_mille if a.has_torque_actual else self._tau[j]
            powered = powered and a.state in POWERED
        return self._flags(rep, powered)

    def _send(self, t_s: float) -> None:
        self.master.transmit(t_s, self._pos, self._vel, self._tau)
