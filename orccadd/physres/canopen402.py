"""`canopen402` backend: an arm of CiA 402 drives on a CANopen bus (SocketCAN, or socketcand).

The resource maps the Physical Resource contract onto the drives (`drivers.canopen.master`):

- configure: the startup sequence (reset, boot-up, PDO mapping, heartbeats, mode), SYNC on;
- activate(mode): the drives' mode (POSITION = CSP, VELOCITY = CSV, TORQUE = CST), then
  each drive walked to OPERATION ENABLED holding where it is;
- read: the frames of the last cycle (positions in increments and torques in per mille through
  the gear; velocity from successive positions), and the watchdogs: a drive fault (EMCY) is
  FAULT, a lost heartbeat, a silent node, a reboot or a dead bus is COMM_LOST, both type 3;
- write: the RPDOs, the active mode's target from the command and the other target holding;
- safe_stop: quick stop on every axis (each drive ramps down at its own quick-stop
  deceleration and switches off, option code 2); STOPPED once every drive is off;
- reset_fault / clear_stop: fault reset (rising edge of bit 7), then back to OPERATION ENABLED;
- switch_mode: 0x6060 by non-blocking SDO writes, answered within `sdo_timeout_s`.

While the base class ignores commands (stopping, stopped, re-enabling), `read` keeps sending
the RPDOs, so the drives always get their controlword and a target that holds the position.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.master import MODE_CODES, CanopenMaster
from orccadd.drivers.canopen.settings import CanopenSettings, load_canopen_settings
from orccadd.errors import ResourceError
from orccadd.model import RobotModel
from orccadd.physres.base import CommandMode, FloatArray, JointState, PhysicalResource, Status

MODE_OF = {
    CommandMode.POSITION: cia402.MODE_CSP,
    CommandMode.VELOCITY: cia402.MODE_CSV,
    CommandMode.TORQUE: cia402.MODE_CST,
}
COMMAND_OF = {v: k for k, v in MODE_OF.items()}
POWERED = (cia402.State.OPERATION_ENABLED, cia402.State.QUICK_STOP_ACTIVE, cia402.State.FAULT_REACTION_ACTIVE)
VELOCITY_FILTER = 0.5  # first-order filter weight of the newest position difference


class Canopen402Arm(PhysicalResource):
    Settings = CanopenSettings

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> CanopenSettings:
        return load_canopen_settings(raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        s: CanopenSettings = config.backend_settings
        self.settings = s
        self.master = CanopenMaster(s, list(config.joint_names), config.control_period_s)
        first = COMMAND_OF[MODE_CODES[s.mode]]
        partner = CommandMode.POSITION if first is CommandMode.TORQUE else CommandMode.TORQUE
        self.supported_modes = frozenset({first, partner})  # type: ignore[misc]  # narrowed at configure
        n = self.dof
        self._pos = np.zeros(n)
        self._vel = np.zeros(n)
        self._tau = np.zeros(n)
        self._enabling = False
        self._fault_reset = False
        self._stop_t0 = 0.0
        self._data = model.new_data()

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        for w in self.master.start():
            print(f"orccadd: warning: {self.name}: {w}", file=sys.stderr)
        modes = frozenset.intersection(*(a.modes for a in self.master.axes))
        self.supported_modes = frozenset(COMMAND_OF[m] for m in modes)  # type: ignore[misc]
        self._wait(lambda: all(a.tpdo_seen_s for a in self.master.axes), "a first TPDO from every drive")

    def _on_activate(self, mode: CommandMode) -> None:
        self._set_mode_blocking(mode)
        self._enable_blocking()

    def _on_switch_mode(self, mode: CommandMode) -> None:
        self.master.write_mode(MODE_OF[mode])

    def _on_deactivate(self) -> None:
        for a in self.master.axes:
            a.controlword = cia402.CW_SHUTDOWN  # power stage off, still ready
        self._pump(0.1)

    def _on_shutdown(self) -> None:
        self.master.close()

    def _on_clear_stop(self) -> None:
        self._enable_blocking()

    def reset_fault(self) -> None:
        """Fault reset on every faulted drive (not for a tick): the control thread's reads send it."""
        for a in self.master.axes:
            a.sdo_error = ""
            a.emcy_code = 0
            a.emcy_text = ""
        self._fault_reset = True
        self.fault_message = ""

    # ---- helpers for the blocking phases (the loop may or may not be ticking) -------------
    def _ticking(self) -> bool:
        t0 = self.master.tick
        time.sleep(3 * self.config.control_period_s)
        return self.master.tick != t0

    def _pump(self, seconds: float) -> None:
        """Run read cycles ourselves for `seconds` when no control loop does."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._cycle_without_loop()

    def _cycle_without_loop(self) -> None:
        self._read_into(time.monotonic(), self.state)
        time.sleep(self.config.control_period_s)

    def _wait(self, done: Any, what: str) -> None:
        end = time.monotonic() + self.settings.startup_timeout_s
        looped = self.master.tick > 0 and self._ticking()
        while not done():
            if time.monotonic() > end:
                states = ", ".join(f"{a.node_id}: {a.state.name}" for a in self.master.axes)
                limit = self.settings.startup_timeout_s
                raise ResourceError(f"resource {self.name!r}: no {what} within {limit:g} s (drives {states})")
            if looped:
                time.sleep(self.config.control_period_s)
            else:
                self._cycle_without_loop()

    def _set_mode_blocking(self, mode: CommandMode) -> None:
        code = MODE_OF[mode]
        if all(a.mode_code == code and a.sdo_pending is None for a in self.master.axes):
            return
        self.master.write_mode(code)
        self._wait(
            lambda: all(a.sdo_pending is None for a in self.master.axes),
            f"answer to the mode change ({mode.name.lower()})",
        )
        errors = [a.sdo_error for a in self.master.axes if a.sdo_error]
        if errors:
            raise ResourceError(f"resource {self.name!r}: {errors[0]}")

    def _enable_blocking(self) -> None:
        self._hold_here()
        self._enabling = True
        try:
            self._wait(
                lambda: all(a.state is cia402.State.OPERATION_ENABLED for a in self.master.axes),
                "OPERATION ENABLED on every drive",
            )
        finally:
            self._enabling = False
        for a in self.master.axes:
            a.controlword = cia402.CW_ENABLE_OPERATION
        self._hold_here()

    def _hold_here(self) -> None:
        """Targets that keep the arm where it is: its position, no speed, gravity torque."""
        q = self.state.q_rad
        self._pos[:] = q
        self._vel[:] = 0.0
        self._tau[:] = pin.computeGeneralizedGravity(self.model.model, self._data, q)

    # ---- tick hooks -------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState) -> int:
        m = self.master
        rep = m.receive(time.monotonic())
        flags = 0
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
        if rep.comm_lost:
            flags |= Status.COMM_LOST
            self.fault_message = rep.comm_lost
        elif rep.fault:
            flags |= Status.FAULT
            self.fault_message = rep.fault
            state.fault_code = rep.fault_code
        if not powered:
            flags |= Status.TORQUE_OFF
        if self._stop_flags or self._enabling or self._fault_reset:
            self._sequence(rep.comm_lost != "")
            m.transmit(time.monotonic(), self._pos, self._vel, self._tau)
        return flags

    def _sequence(self, comm_lost: bool) -> None:
        """Controlwords while commands are ignored: quick stop, fault reset, or enabling."""
        m = self.master
        if self._fault_reset:
            done = True
            for a in m.axes:
                if a.state is cia402.State.FAULT:
                    a.controlword = (
                        cia402.CW_FAULT_RESET
                        if a.controlword != cia402.CW_FAULT_RESET
                        else cia402.CW_DISABLE_VOLTAGE
                    )
                    done = False
            self._fault_reset = not done
            return
        if self._enabling:
            for a in m.axes:
                cw = cia402.command_towards(a.state)
                if cw == cia402.CW_FAULT_RESET and a.controlword == cia402.CW_FAULT_RESET:
                    cw = cia402.CW_DISABLE_VOLTAGE  # for a rising edge next time
                if cw is not None:
                    a.controlword = cw
            return
        if self._stop_flags & Status.STOPPING:
            off = True
            for a in m.axes:
                if a.state is cia402.State.OPERATION_ENABLED:
                    a.controlword = cia402.CW_QUICK_STOP
                off = off and a.state not in POWERED
            timed_out = time.monotonic() - self._stop_t0 > self.config.safe_stop.timeout_s
            if off or (comm_lost and timed_out):  # unreachable drives stop on their own watchdogs
                self._mark_stopped(torque_off=True)

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
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
        self.master.transmit(time.monotonic(), self._pos, self._vel, self._tau)
        return 0

    def _begin_safe_stop(self) -> None:
        self._stop_t0 = time.monotonic()
        self._pos[:] = self.state.q_rad
        self._vel[:] = 0.0
        for a in self.master.axes:
            if a.state is cia402.State.OPERATION_ENABLED:
                a.controlword = cia402.CW_QUICK_STOP
        self.master.transmit(time.monotonic(), self._pos, self._vel, self._tau)
