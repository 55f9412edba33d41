"""`dynamixel` backend: an arm of DYNAMIXEL X servos on one half-duplex bus (Protocol 2.0, a U2D2
or any TTL/RS-485 adapter), through ROBOTIS's `dynamixel_sdk` (`orccadd.drivers.dynamixel`).

- configure: the USB adapter's latency timer against the period (a one-line fix if it is the
  16 ms default); every ID pinged and its model number checked against the config; a hardware
  error latched from before cleared by a reboot; the EEPROM items (return delay 0, operating
  mode, limits) written where they differ, only with the torque off (`drivers.dynamixel.startup`);
- activate(mode): each servo's operating mode for `mode`, Profile Velocity/Acceleration 0 (the
  goals stream), the goal that holds where the arm is (Goal Position = Present Position: a servo
  switched on keeps its old goal otherwise; Goal Velocity 0; Goal Current = gravity), then
  Torque Enable, last;
- read: one Fast Sync Read of Present Current (XL430: Load), Velocity and Position of every
  servo; a servo whose error byte carries the alert bit gets its Hardware Error Status read once:
  FAULT naming the servo and the bit; failed reads (timeouts, CRC) are counted and
  `comm_errors_in_a_row` of them are CommLost, naming the servo where the reply stopped (the
  servo is then left out of the cycle so the others can still be read and stopped);
- write: one Sync Write of the mode's goal (Position, Velocity or Current);
- switch_mode: Operating Mode is EEPROM, so the servos take it with the torque off: one burst of
  Sync Writes (torque off, mode, the new mode's holding goal, torque on) with nothing between
  them: the servos are unpowered for the wire time of three packets (~0.1 ms at 4 Mbit/s, a
  few ms through a USB adapter), in which a loaded arm falls by micro-radians. A switch that the
  servos did not all take (checked by reading the modes back) is a FAULT, never a half switch;
- safe stop: category 1 or 2 follow our deceleration ramp at `deceleration_rad_s2` through the
  goal stream (positions; or velocities and currents tracking it), then hold; category 1 then
  switches the torque off, only where `torque_off_at_rest` says the arm rests safely unpowered
  (the servos have no brakes); category 0 (torque off at once) is refused at config time on an
  arm loaded by gravity (`check_description`);
- reset_fault: the faulted servos are rebooted (Reboot instruction), answer again, show no
  hardware error, and are re-enabled holding where they are if the rest of the arm is enabled;
  a lost servo that answers again is rebooted the same way. It blocks for the servos' boot
  (`reboot_timeout_s`), the bus shared with the ticks transaction by transaction;
- the port gone (the USB adapter unplugged; `drivers.dynamixel.port`): CommLost naming the port
  in the first tick that finds it, and from then on the ticks touch nothing (no servo can be
  read or commanded). The safe stop cannot reach the servos: each holds its last goal (position
  modes; the ramp's or the motion's, one period ahead) or stops on its Bus Watchdog
  (`bus_watchdog_ms`, velocity and current modes), so the stop counts as done once that time
  has passed since the last goal went out. `reset` opens the port again (refused naming it while
  the device is absent), checks the chain as configure does (latency timer, models, latched
  errors, EEPROM, the operating modes of the mode it was in, each servo's torque as found) and
  holds where the arm now is; `clear_stop` then enables the servos that are off.

In velocity and current modes the servos' Bus Watchdog(98) stops them if the bus goes quiet
for `bus_watchdog_ms` (this process died or stalled: a Goal Current left alone would accelerate
the arm); it is re-armed after a gap in the ticks. Position mode needs none: a servo holds its
last goal.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel import wire
from orccadd.drivers.dynamixel.chain import READ_LOST, READ_OK, READ_TIMEOUT, ChainError, ServoChain
from orccadd.drivers.dynamixel.errors import ALERT, hardware_error_text
from orccadd.drivers.dynamixel.goals import Goals
from orccadd.drivers.dynamixel.models import MODE_NAMES, MODELS
from orccadd.drivers.dynamixel.port import check_latency, failure_text
from orccadd.drivers.dynamixel.settings import DynamixelSettings, load_dynamixel_settings
from orccadd.drivers.dynamixel.startup import eeprom_targets, goal_item, operating_modes
from orccadd.errors import ResourceError
from orccadd.fault import FaultKind
from orccadd.model import RobotModel
from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import MEASURED, Quantity, ResourceDescription, Source
from orccadd.physres.stop_ramp import StopRamp
from orccadd.state import FloatArray, JointState
from orccadd.types import CommandMode, Status

FAST_READ_FIRMWARE = 45  # X-series firmware with Fast Sync Read (ROBOTIS e-Manual)
log = logging.getLogger("orccadd.dynamixel")

AT_REST_RAD_S = 0.05  # two velocity units (0.024 rad/s each) at the horn
AT_REST_TICKS = 3
COMM_LOST = int(Status.COMM_LOST)
FAULT = int(Status.FAULT)
TORQUE_OFF = int(Status.TORQUE_OFF)
STOPPING = int(Status.STOPPING)
STOPPED = int(Status.STOPPED)


class DynamixelArm(PhysicalResource):
    Settings = DynamixelSettings

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        s: DynamixelSettings = config.backend_settings
        return (f"serial port {s.port}",)  # one chain per port (servos of one chain: one resource)

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        s: DynamixelSettings = config.backend_settings
        modes = {CommandMode.POSITION, CommandMode.VELOCITY}
        if s.has_current:
            modes.add(CommandMode.TORQUE)
        basis = (
            "Present Current × the model's torque constant (stall torque / stall current)"
            if s.has_current
            else "Present Load (0.1 % of the stall torque)"
        )
        servos = ", ".join(f"{v.id}: {v.model}" for v in s.servos)
        return ResourceDescription(
            backend="dynamixel",
            joints=config.joint_names,
            modes=frozenset(modes),
            mode_switch_needs_disable=True,  # Operating Mode is EEPROM: written with torque off
            position=MEASURED,
            velocity=MEASURED,
            torque=Quantity(Source.ESTIMATED, basis),
            brakes=False,
            stop_categories=frozenset({0, 1, 2} if s.torque_off_at_rest else {0, 2}),
            read_time_s=s.read_time_s(),
            write_time_s=s.write_time_s(),
            fault_reset=True,
            extra={"port": s.port, "baud_rate": str(s.baud_rate), "servos": servos},
        )

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> DynamixelSettings:
        return load_dynamixel_settings(raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        s: DynamixelSettings = config.backend_settings
        self.settings = s
        self.chain = ServoChain(s, config.joint_names)
        self.targets = eeprom_targets(s, config)
        self.goals = Goals(s.units(), self.targets, model)
        n = self.dof
        self._goal = [0] * n  # the last goals sent (units of the active mode)
        self._enabled = [False] * n  # torque on, as we set it (a hardware error switches it off)
        self._hw_error = [0] * n  # latched Hardware Error Status bits per servo
        self._lost = [False] * n
        self._comm_lost = ""
        self._port_gone = ""  # why the port is gone: set by the tick that finds it, cleared by reset
        self._silent = False  # this tick found the port gone: nothing goes to the servos
        self._switch_fault = ""
        self._fault_key: tuple[object, ...] = ()
        self._op_modes = [MODE_NAMES[v.operating_mode] for v in s.servos]
        self._ramp = StopRamp(n)
        self._mode_targets: dict[CommandMode, list[int]] = {}  # each servo's Operating Mode, per mode
        self._holding = False  # ticks without a command since the last one (keep-alive holds)
        self._rest_ticks = 0
        self._stop_t0 = 0.0
        self._watchdog = math.ceil(s.bus_watchdog_ms * 1e-3 / T.BUS_WATCHDOG_UNIT_S)
        self._watchdog_armed = False
        self._last_send_s = 0.0
        self.latency_s = 0.0
        self.sync_read = "fast sync read" if s.fast_sync_read else "sync read (fast_sync_read = false)"

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        s, ch = self.settings, self.chain
        busy = s.read_time_s() + s.write_time_s()
        self.latency_s = check_latency(s.port, self.config.control_period_s, busy, set_it=s.set_latency_timer)
        ch.open(self.latency_s)
        try:
            self._check_chain(self._op_modes)
        except Exception:
            ch.close()
            raise
        self.goals.set_operating_modes(self._op_modes)

    def _check_chain(self, modes: Sequence[int]) -> None:
        """Every servo: its model, the sync read it can do, a hardware error latched from before
        (rebooted), its EEPROM (written where it differs, Operating Mode `modes[j]`: only with
        the torque off), its torque as found. At configure, and in a reset after the port was lost."""
        ch = self.chain
        for j, servo in enumerate(self.settings.servos):
            ch.check_model(j, MODELS[servo.model].model_number)
        self.sync_read = self._choose_sync_read()
        for j in range(self.dof):
            if bits := ch.read(j, T.HARDWARE_ERROR_STATUS):
                log.warning(
                    "%s: %s latched from before: rebooting it", ch.labels[j], hardware_error_text(bits)
                )
                self._reboot(j)
        for j, target in enumerate(self.targets):
            block = ch.read_bytes(j, 0, T.EEPROM_END)
            diff = target.differences(block)
            diff.pop(T.OPERATING_MODE, None)
            if T.OPERATING_MODE.decode(block, T.OPERATING_MODE.address) != modes[j]:
                diff[T.OPERATING_MODE] = modes[j]
            on = bool(ch.read(j, T.TORQUE_ENABLE))
            if diff and on:
                items = ", ".join(f"{item} = {v}" for item, v in diff.items())
                raise ResourceError(
                    f"{self.name}: {ch.labels[j]} has its torque on and needs {items} (EEPROM, "
                    "written only with the torque off): switch it off with the arm supported"
                )
            for item, v in diff.items():
                ch.write(j, item, v)
            self._enabled[j] = on

    def _choose_sync_read(self) -> str:
        """Fast Sync Read where every servo's firmware has it (45 and up), else a plain Sync Read
        (one status packet per servo, each held by the adapter's latency timer): refused where
        that no longer fits in the period. What was chosen and why, for `describe`."""
        s, ch = self.settings, self.chain
        if not s.fast_sync_read:
            ch.fast = False
            return "sync read (fast_sync_read = false)"
        old = [
            (j, fw) for j in range(self.dof) if (fw := ch.read(j, T.FIRMWARE_VERSION)) < FAST_READ_FIRMWARE
        ]
        ch.fast = not old
        if not old:
            return "fast sync read"
        who = ", ".join(f"{ch.labels[j]} has firmware {fw}" for j, fw in old)
        why = f"{who}, without Fast Sync Read (firmware {FAST_READ_FIRMWARE} and up)"
        plain_s = wire.read_time_s(s.n, T.CYCLIC_LENGTH, s.baud_rate, s.return_delay_us * 1e-6, fast=False)
        busy_s = plain_s + s.write_time_s() + s.n * self.latency_s
        period = self.config.control_period_s
        if busy_s + s.read_timeout_s > period:
            raise ResourceError(
                f"{self.name}: {why}: a plain sync read of the chain takes {busy_s * 1e3:.3g} ms with the "
                f"write and the adapter's latency, which with read_timeout_s = {s.read_timeout_s:g} does "
                f"not fit in control_period_s = {period:g}. Update the servos' firmware (DYNAMIXEL "
                "Wizard 2.0), or lengthen control_period_s"
            )
        self.description = dataclasses.replace(self.description, read_time_s=plain_s)
        log.warning("%s: %s: the cyclic read is a plain sync read (%.3g ms)", self.name, why, busy_s * 1e3)
        return f"sync read: {why}"

    def _on_activate(self, mode: CommandMode) -> None:
        """Operating modes, profiles off, then every servo enabled holding where it is (a servo
        left enabled by an earlier run is switched by the same burst as a mode switch)."""
        ch = self.chain
        target = operating_modes(self.settings, self.config, mode)
        everyone = dict.fromkeys(range(self.dof), 0)
        ch.sync_write(T.PROFILE_ACCELERATION, everyone)
        ch.sync_write(T.PROFILE_VELOCITY, everyone)
        for j in range(self.dof):  # the others get theirs when enabled (`_enable`)
            if self._enabled[j]:
                for gain, value in self.settings.servos[j].position_gains():
                    ch.write(j, gain, value)
        if any(self._enabled):
            self._switch(mode, target)
            self._check_switch(target)
        else:
            ch.sync_write(T.BUS_WATCHDOG, everyone)
            for j, m in enumerate(target):
                if m != self._op_modes[j]:
                    ch.write(j, T.OPERATING_MODE, m)
            self._set_modes(target)
        self._read_blocking()
        self._enable([j for j in range(self.dof) if not self._enabled[j]])
        self._after_enable(mode, time.monotonic())

    def _after_enable(self, mode: CommandMode, now: float) -> None:
        if not self._watchdog_armed:
            self._arm_watchdog(mode)
        self._read_into(now, self.state)
        self._ramp.hold(self.state.q_rad.tolist(), now)
        self._holding = False

    def _on_prepare_mode_switch(self, mode: CommandMode) -> None:
        self._mode_targets[mode] = operating_modes(self.settings, self.config, mode)

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        if self._port_gone:  # nothing reaches the servos: the reset sets the modes of `mode`
            return
        target = self._mode_targets[mode]
        try:
            self._switch(mode, target)
            self._check_switch(target)
        except (ChainError, OSError) as e:
            self._switch_fault = f"switch to {mode.name.lower()} mode failed: {e}"
            log.error("%s: %s", self.name, self._switch_fault)
        self._ramp.hold(self.state.q_rad.tolist(), self.state.t_s)
        self._holding = False

    def _switch(self, mode: CommandMode, target: list[int]) -> None:
        """One burst: watchdog off, torque off, mode, the new mode's holding goal, torque on."""
        goals = self._holding_goals(mode)
        on = {j: 1 for j in range(self.dof) if self._enabled[j] and self.chain.active[j]}
        live = [j for j in range(self.dof) if self.chain.active[j]]
        writes: list[tuple[T.Item, Mapping[int, int]]] = []
        if self._watchdog_armed:
            writes.append((T.BUS_WATCHDOG, dict.fromkeys(live, 0)))
            self._watchdog_armed = False
        if target != self._op_modes:
            writes += [
                (T.TORQUE_ENABLE, dict.fromkeys(on, 0)),
                (T.OPERATING_MODE, {j: target[j] for j in live}),
            ]
        writes.append((goal_item(mode), {j: goals[j] for j in live}))
        if target != self._op_modes:
            writes.append((T.TORQUE_ENABLE, on))
        self.chain.burst([(item, values) for item, values in writes if values])
        self._set_modes(target)
        self._goal = goals
        self._arm_watchdog(mode)

    def _check_switch(self, target: list[int]) -> None:
        shown = self.chain.sync_read(T.OPERATING_MODE)
        wrong = [j for j, m in shown.items() if m != target[j]]
        if wrong:
            j = wrong[0]
            raise ChainError(f"{self.chain.labels[j]} shows Operating Mode {shown[j]}, not {target[j]}")
        torque = self.chain.sync_read(T.TORQUE_ENABLE)
        off = [j for j, v in torque.items() if self._enabled[j] and not v]
        if off:
            raise ChainError(f"{self.chain.labels[off[0]]} did not take Torque Enable back")

    def _set_modes(self, modes: list[int]) -> None:
        self._op_modes = list(modes)
        self.goals.set_operating_modes(modes)

    def _on_deactivate(self) -> None:
        if self._port_gone or self.chain.lost:
            log.warning(
                "%s: the port %s is gone: the servos are left as they are", self.name, self.settings.port
            )
            return
        try:
            self._disarm_watchdog()
        except ChainError as e:
            log.warning("%s: %s", self.name, e)
        for j in range(self.dof):
            if self.chain.active[j]:
                try:
                    self.chain.write(j, T.TORQUE_ENABLE, 0)
                except ChainError as e:
                    log.warning("%s: %s", self.name, e)
            self._enabled[j] = False

    def _on_shutdown(self) -> None:
        self.chain.close()

    def _on_clear_stop(self) -> None:
        """Re-enable every servo that is off (category 0 or 1, a rebooted one), holding where
        it is; the ones on keep holding."""
        self._ramp.hold(self.state.q_rad.tolist(), self.state.t_s)
        off = [j for j in range(self.dof) if not self._enabled[j] and self.chain.active[j]]
        if off:
            self._enable(off)
        self._holding = False

    def _enable(self, joints: list[int]) -> None:
        """Goals that hold joints `joints` where they are, then Torque Enable (not for a tick)."""
        ch = self.chain
        for j in joints:
            if self._watchdog_armed:  # an expired watchdog makes the goals read-only: clear it
                ch.write(j, T.BUS_WATCHDOG, 0)
            raw = ch.read_bytes(j, T.CYCLIC_START, T.CYCLIC_LENGTH)
            ch.present_position[j] = T.PRESENT_POSITION.decode(
                raw, T.PRESENT_POSITION.address - T.CYCLIC_START
            )
        q = self.goals.joint_positions(ch.present_position)
        for j in joints:
            self._ramp.q_rad[j] = q[j]
        mode = self.mode
        goals = self._holding_goals(mode)
        item = goal_item(mode)
        for j in joints:
            for gain, value in self.settings.servos[j].position_gains():
                ch.write(j, gain, value)
            self._goal[j] = goals[j]
            ch.write(j, item, goals[j])
            ch.write(j, T.TORQUE_ENABLE, 1)
            self._enabled[j] = True
        if self._watchdog_armed:
            for j in joints:
                ch.write(j, T.BUS_WATCHDOG, self._watchdog)

    def _on_reset_fault(self) -> None:
        """Reboot the faulted (and lost) servos, check they came back clean, re-enable them if
        the rest of the arm is enabled. Blocks for their boot (see the module's doc). After the
        port was lost: `_reconnect`."""
        if self._port_gone:
            self._reconnect()
            return
        ch = self.chain
        bad = [j for j in range(self.dof) if self._hw_error[j] or self._lost[j]]
        hold = any(self._enabled[j] for j in range(self.dof) if j not in bad)
        for j in bad:
            ch.set_active(j, False)
            self._enabled[j] = False
            try:
                self._reboot(j)
                ch.check_model(j, MODELS[self.settings.servos[j].model].model_number)
                if ch.read(j, T.OPERATING_MODE) != self._op_modes[j]:
                    ch.write(j, T.OPERATING_MODE, self._op_modes[j])
                self._hw_error[j] = 0
                self._lost[j] = False
            finally:
                if not self._lost[j]:
                    ch.set_active(j, True)  # read again, faulted or not
        if hold and bad:
            self._enable(bad)
        if self._switch_fault:  # a switch the servos did not all take: make it again, checked
            target = operating_modes(self.settings, self.config, self.mode)
            self._op_modes = [-1] * self.dof
            self._switch(self.mode, target)
            self._check_switch(target)
        self._clear_faults()

    def _clear_faults(self) -> None:
        self._comm_lost = ""
        self._switch_fault = ""
        self.chain.in_a_row = 0
        self.fault = None
        self.state.fault_code = 0

    def _reconnect(self) -> None:
        """After the port was lost, the arm safe-stopped: the port opened again (refused naming it
        while the device is still absent), the chain checked as at configure with the operating
        modes of the current mode (servos powered off meanwhile have lost their RAM), the state
        read, and the stop's hold taken from where the arm now is; only then do the ticks read
        and send again. Blocks (the checks, a reboot)."""
        s, ch = self.settings, self.chain
        busy = s.read_time_s() + s.write_time_s()
        # an adapter plugged again may be another one: its latency timer checked as at configure
        self.latency_s = check_latency(s.port, self.config.control_period_s, busy, set_it=s.set_latency_timer)
        try:
            ch.reopen(self.latency_s)
        except ResourceError as e:
            raise ResourceError(
                f"{self.name}: the port {s.port} is still gone ({e}): plug its adapter back in, "
                "then reset again"
            ) from None
        self._lost = [False] * self.dof
        self._hw_error = [0] * self.dof
        for j in range(self.dof):
            ch.set_active(j, True)
        mode = self.mode
        target = operating_modes(s, self.config, mode)
        self._check_chain(target)
        self._set_modes(target)
        everyone = dict.fromkeys(range(self.dof), 0)
        ch.sync_write(T.PROFILE_ACCELERATION, everyone)
        ch.sync_write(T.PROFILE_VELOCITY, everyone)
        self._read_blocking()
        self._ramp.hold(self.goals.joint_positions(ch.present_position), self.state.t_s)
        self._goal = self._holding_goals(mode)
        self._holding = False
        self._watchdog_armed = bool(self._watchdog) and mode is not CommandMode.POSITION
        if self._watchdog_armed:  # cleared (a servo that stayed on has seen it expire), then set
            self._rearm_watchdog()
        log.info("%s: the port %s is open again, the servos checked", self.name, s.port)
        self._clear_faults()
        self._port_gone = ""  # last: the ticks read and send again

    def _reboot(self, j: int) -> None:
        ch = self.chain
        ch.reboot(j)
        ch.wait_answering(j, self.settings.reboot_timeout_s)
        if bits := ch.read(j, T.HARDWARE_ERROR_STATUS):
            raise ResourceError(
                f"{self.name}: {ch.labels[j]} still reports {hardware_error_text(bits)} after a reboot"
            )

    def _read_blocking(self) -> None:
        for _ in range(5):
            if self.chain.read_cycle() == READ_OK:
                return
        s = self.settings
        raise ResourceError(f"{self.name}: no complete sync read of the servos on {s.port} in 5 tries")

    def _holding_goals(self, mode: CommandMode) -> list[int]:
        """Goals that hold the arm where the last read saw it, in `mode`."""
        if mode is CommandMode.POSITION:
            return list(self.chain.present_position)
        if mode is CommandMode.VELOCITY:
            return [0] * self.dof
        return self.goals.gravity(self.goals.joint_positions(self.chain.present_position))

    # ---- the bus watchdog (velocity and current modes) -----------------------------------------
    def _arm_watchdog(self, mode: CommandMode) -> None:
        if self._watchdog and mode is not CommandMode.POSITION:
            live = [j for j in range(self.dof) if self.chain.active[j]]
            self.chain.sync_write(T.BUS_WATCHDOG, dict.fromkeys(live, self._watchdog))
            self._watchdog_armed = True

    def _disarm_watchdog(self) -> None:
        if self._watchdog_armed:
            self.chain.sync_write(T.BUS_WATCHDOG, dict.fromkeys(range(self.dof), 0))
            self._watchdog_armed = False

    # ---- tick hooks -------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState) -> int:
        ch = self.chain
        if self._port_gone:  # until a reset opens it again: nothing read, nothing sent
            self._silent = True
            return self._flags(state)
        self._silent = False
        try:
            result = ch.read_cycle()
        except OSError as e:  # the port answers its failures as READ_LOST: this is unforeseen
            self._lose_port(failure_text(e))
            return self._flags(state)
        if result == READ_LOST:
            self._lose_port(ch.lost)
            return self._flags(state)
        g = self.goals
        if result == READ_OK:
            q = g.joint_positions(ch.present_position)
            dq = [v * k for v, k in zip(ch.present_velocity, g.rad_s_per_unit, strict=True)]
            tau = [c * k for c, k in zip(ch.present_current, g.nm_per_unit, strict=True)]
            state.vector[:] = q + dq + tau
            for j, err in enumerate(ch.error_byte):
                if err & ALERT and self._hw_error[j] in (0, ALERT) and ch.active[j]:  # ALERT: not read yet
                    self._hardware_error(j)
        elif ch.in_a_row >= self.settings.comm_errors_in_a_row:
            self._comm_errors()
        return self._flags(state)

    def _hardware_error(self, j: int) -> None:
        """Servo j's alert bit: its Hardware Error Status, read (one transaction). A read that
        fails leaves ALERT (bit 7, which the register never sets) and is tried again next tick."""
        try:
            bits = self.chain.read(j, T.HARDWARE_ERROR_STATUS, patient=False) or ALERT
        except (ChainError, OSError):
            bits = ALERT
        self._hw_error[j] = bits
        self._enabled[j] = False  # a hardware error switches the servo's torque off

    def _comm_errors(self) -> None:
        ch = self.chain
        n = self.settings.comm_errors_in_a_row
        j = ch.cut_at
        waited = (
            f"each reply waited for {ch.cycle_deadline_s() * 1e3:.2f} ms, its wire time plus "
            f"read_timeout_s = {self.settings.read_timeout_s * 1e3:g} ms and the adapter's latency"
        )
        if ch.last_result == READ_TIMEOUT and j >= 0:
            why = f"{n} sync reads in a row stopped at its reply; {waited}"
            self._lose(j, f"{ch.labels[j]} does not answer: {why}")
        else:
            what = "damaged (CRC)" if ch.last_result != READ_TIMEOUT else "missing"
            counts = f"{ch.timeouts} timeouts, {ch.crc_errors} CRC errors in {ch.reads} reads"
            self._lose(-1, f"{n} sync reads in a row failed, the last reply {what} ({counts}; {waited})")
        ch.in_a_row = 0

    def _lose_port(self, why: str) -> None:
        """The port is gone (the rare path of a tick: its words made once): CommLost naming it,
        and the ticks leave the servos alone until a reset."""
        self._silent = True
        self._port_gone = (
            f"the port {self.settings.port} is gone ({why}): no servo can be read or commanded; "
            "`reset` opens it again once its adapter is back"
        )
        self._comm_lost = self._port_gone  # what any servo's silence before it was about

    def _lose(self, j: int, why: str) -> None:
        if j >= 0:
            self._lost[j] = True
            self._enabled[j] = False
            self.chain.set_active(j, False)  # the others can still be read and stopped
        if not self._comm_lost:
            self._comm_lost = why

    def _flags(self, state: JointState) -> int:
        flags = 0
        key = (self._comm_lost, self._switch_fault, *self._hw_error)
        if key != self._fault_key:  # messages built only when the faults change
            self._fault_key = key
            self._fault_text(state)
        if self._comm_lost:
            flags |= COMM_LOST
        if self._switch_fault or any(self._hw_error):
            flags |= FAULT
        if not any(self._enabled):
            flags |= TORQUE_OFF
        return flags

    def _fault_text(self, state: JointState) -> None:
        parts = [m for m in (self._comm_lost, self._switch_fault) if m]
        ch = self.chain
        joint, code = "", 0  # the first servo in hardware error, its bits
        for j, bits in enumerate(self._hw_error):
            if bits:
                what = "not read yet (alert)" if bits == ALERT else hardware_error_text(bits)
                parts.append(f"{ch.labels[j]}: hardware error: {what}")
                if not joint:
                    joint, code = self.model.joint_names[j], bits
                if not state.fault_code or state.fault_code & 0xFF == ALERT:  # the real bits, once read
                    state.fault_code = ch.ids[j] << 8 | bits
        if parts:
            kind = FaultKind.COMM_LOST if self._comm_lost else FaultKind.DEVICE
            whole = self._comm_lost or self._switch_fault  # about the chain, not one servo
            self._set_fault(kind, "; ".join(parts), "" if whole else joint, 0 if whole else code)

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        self._holding = False
        return self._send(t_s, mode, self.goals.command(mode, command.tolist()))

    def _send(self, t_s: float, mode: CommandMode, goals: list[int]) -> int:
        self._goal = goals
        if self._silent:  # the port is gone: nothing can be sent
            return COMM_LOST
        ch = self.chain
        try:
            if (
                self._watchdog_armed
                and t_s - self._last_send_s > 0.5 * self._watchdog * T.BUS_WATCHDOG_UNIT_S
            ):
                self._rearm_watchdog()
            self._last_send_s = t_s
            ch.write_goals(goal_item(mode), goals)
        except (OSError, ChainError) as e:
            if not ch.lost:
                self._lose(-1, f"the port {self.settings.port} failed: {e}")
                self._flags(self.state)  # the fault in words now: this tick's type 3 reports it
                return COMM_LOST
        if ch.lost:  # found gone by this write
            self._lose_port(ch.lost)
            self._flags(self.state)
            return COMM_LOST
        return 0

    def _rearm_watchdog(self) -> None:
        """After a gap in the ticks: clear an expired watchdog (goals are refused until then)."""
        live = {j: 0 for j in range(self.dof) if self.chain.active[j]}
        self.chain.burst([(T.BUS_WATCHDOG, live), (T.BUS_WATCHDOG, dict.fromkeys(live, self._watchdog))])

    def _follow(self, t_s: float) -> None:
        st, r = self.state, self._ramp
        goals = self.goals.follow(
            self.mode, r.q_rad, r.dq_rad_s, r.ddq_rad_s2, st.q_rad.tolist(), st.dq_rad_s.tolist()
        )
        self._send(t_s, self.mode, goals)

    def _on_keep_alive(self, t_s: float) -> None:
        """No command this tick: the stop's ramp, or the goals that hold the arm."""
        stop = self._stop_flags
        if stop & STOPPING:
            self._stop_step(t_s)
        elif not any(self._enabled):
            return
        elif stop & STOPPED:
            self._follow(t_s)
        else:
            if not self._holding:
                self._holding = True
                self._ramp.hold(self.state.q_rad.tolist(), t_s)
            if self.mode is CommandMode.POSITION:
                self._send(t_s, self.mode, self._goal)
            else:
                self._follow(t_s)

    def _begin_safe_stop(self) -> None:
        st = self.state
        self._stop_t0 = st.t_s
        self._rest_ticks = 0
        if self.config.safe_stop.category == 0:
            if not self._silent:
                self._torque_off_all()
            return
        start = self._last_pos_cmd if self.mode is CommandMode.POSITION else st.q_rad
        live = [self._enabled[j] and self.chain.active[j] for j in range(self.dof)]
        dq = [v if on else 0.0 for v, on in zip(st.dq_rad_s.tolist(), live, strict=True)]
        self._ramp.start(start.tolist(), dq, st.t_s)

    def _stop_step(self, t_s: float) -> None:
        cfg = self.config.safe_stop
        if self._silent:  # the port is gone: the servos stop on their own (see the module)
            watchdog_s = self._watchdog * T.BUS_WATCHDOG_UNIT_S if self._watchdog_armed else 0.0
            if t_s - self._last_send_s >= watchdog_s:
                self._mark_stopped(False)
            return
        if cfg.category != 0:
            self._ramp.step(t_s, cfg.deceleration_rad_s2)
            if any(self._enabled):
                self._follow(t_s)
            if not self._ramp.done:
                return
        enabled = [j for j in range(self.dof) if self._enabled[j]] or range(self.dof)
        dq = self.state.dq_rad_s
        slow = all(abs(dq[j]) < AT_REST_RAD_S for j in enabled)
        self._rest_ticks = self._rest_ticks + 1 if slow else 0
        if self._rest_ticks >= AT_REST_TICKS or t_s - self._stop_t0 > cfg.timeout_s:
            torque_off = cfg.category in (0, 1)
            if cfg.category == 1:
                self._torque_off_all()
            self._mark_stopped(torque_off)

    def _torque_off_all(self) -> None:
        live = {j: 0 for j in range(self.dof) if self.chain.active[j]}
        try:
            self.chain.burst([(T.TORQUE_ENABLE, live)])
        except (ChainError, OSError) as e:
            log.error("%s: torque off: %s", self.name, e)
        self._enabled = [False] * self.dof

    # ---- diagnostics ----------------------------------------------------------------------
    def _details(self) -> dict[str, float | int | str]:
        ch = self.chain
        lost = ", ".join(ch.labels[j] for j in range(self.dof) if self._lost[j])
        errors = "; ".join(
            f"{ch.labels[j]}: {hardware_error_text(b)}" for j, b in enumerate(self._hw_error) if b
        )
        return {
            **super()._details(),
            "port": self.settings.port,
            "baud_rate": self.settings.baud_rate,
            "latency_timer_ms": self.latency_s * 1e3,
            "sync_read": self.sync_read,
            "reads": ch.reads,
            "timeouts": ch.timeouts,
            "timeouts_by_servo": ", ".join(
                f"{i}: {n}" for i, n in zip(ch.ids, ch.timeouts_by_servo, strict=True)
            ),
            "late_bytes_dropped": ch.late_bytes_dropped,
            "cycle_deadline_ms": round(ch.cycle_deadline_s() * 1e3, 3) if ch.port is not None else 0.0,
            "crc_errors": ch.crc_errors,
            "lost": lost or "none",
            "hardware_errors": errors or "none",
        }
