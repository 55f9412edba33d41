"""`ur_rtde` backend: a Universal Robots arm (e-Series at 500 Hz, CB3 at 125 Hz) over RTDE, through
the `ur-rtde` package, whose three clients (the RTDE stream, the control script, the dashboard)
the driver object `drivers.ur.link.UrLink` owns with their threads, in a process of its own
(`drivers.ur.link_server`: ur_rtde has crashed the process it runs in after a dropped
connection); this resource is the tick over it (`drivers.ur.remote_link.RemoteLink`): state,
faults, commands and the stop.

- configure: the dashboard first: controller version and robot model checked against the config,
  the controller's period against the control period; power on and brake release only if the
  config says so (`power_on`); then the RTDE stream and the control script;
- the loop is **device-paced**: `wait_for_cycle` returns when a new RTDE package (a new controller
  timestamp) has arrived from the link process; no package for `stall_periods` periods, the links
  down, or the link process ended, is CommLost: the process is ended at once (the controller's
  watchdog then stops its script), and `reset` starts a new one;
- read: actual q and dq (measured), torque = the controller's target moments (estimated from its
  model), and every tick robot mode, safety mode, runtime state and status bits: a protective or
  safeguard stop, an emergency stop, a violation or fault, power off or the control script not
  running is a device fault naming the condition (type 3);
- write: POSITION = servoJ(q, time = period, lookahead, gain), VELOCITY = speedJ(qd, a, period),
  TORQUE = directTorque(tau − g(q)) where the config's `min_version` is 5.26 or later (ur_rtde
  1.6's script has `direct_torque` from 5.26 on; the controller adds gravity itself);
- safe stop (category 1 or 2): our own deceleration ramp at the configured rate, sent through the
  same servoJ/speedJ stream (never a jump), then servoStop/speedStop at rest; category 1 then
  powers the arm off (brakes);
- reset: a protective stop is unlocked once the controller allows it (5 s after it began), the
  safety popup closed and the control script restarted; a lost connection is re-opened (only here,
  when idle); an emergency stop or a violation is refused with what must be done at the pendant.

Stream commands go one way to the link process in the tick; a refusal (the script not running,
ur_rtde raising) comes back and is taken by the next tick.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.drivers.ur.behaviours import (
    FORCE_MODE,
    FORCE_MODE_SIZE,
    FORCE_MODE_UNIT,
    FREEDRIVE,
    FREEDRIVE_SIZE,
    FREEDRIVE_UNIT,
    TOOL,
    TOOL_SIZE,
    TOOL_UNIT,
)
from orccadd.drivers.ur.controller import RobotMode, SafetyMode, parse_polyscope_version
from orccadd.drivers.ur.remote_link import RemoteLink
from orccadd.drivers.ur.settings import NAME, RATED_PAYLOAD_KG, UrRtdeSettings, io_bit, output_action
from orccadd.errors import ConfigError, ResourceError
from orccadd.fault import FaultKind
from orccadd.model import RobotModel
from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import MEASURED, ClockSource, Quantity, ResourceDescription, Signal, Source
from orccadd.physres.stop_ramp import StopRamp
from orccadd.physres.torque_hold import TorqueHold
from orccadd.state import FloatArray, JointState
from orccadd.types import CommandMode, Status

E_SERIES = ("UR3e", "UR5e", "UR10e", "UR16e", "UR20", "UR30")
AT_REST_RAD_S = 0.01
DIRECT_TORQUE_SINCE = (5, 26)  # ur_rtde 1.6's script calls `direct_torque` on 5.26 and later only
NO_FRICTION_SCALE = [0.0] * 6  # what that script passes to `direct_torque`, whatever it is sent
COMMANDS = (
    Signal(FORCE_MODE, FORCE_MODE_SIZE, FORCE_MODE_UNIT, "the controller's force mode (ur_force_mode)"),
    Signal(FREEDRIVE, FREEDRIVE_SIZE, FREEDRIVE_UNIT, "the controller's freedrive (ur_freedrive)"),
    Signal(TOOL, TOOL_SIZE, TOOL_UNIT, "the payload and TCP a task sets at its start (ur_tool)"),
)
SIGNALS = (
    Signal("wrench", 6, "N|N.m", "the TCP's force and torque, base frame (RTDE actual_TCP_force)"),
    Signal("speed_scaling", 1, "1", "the controller's speed scaling: its speed slider times its own"),
)


def direct_torque(config: RobotConfig) -> bool:
    """The config's controllers have direct torque control: its `min_version` (checked at
    connect: an older controller is refused, naming its version) is 5.26 or later."""
    s: UrRtdeSettings = config.backend_settings
    least = parse_polyscope_version(s.min_version)
    return (least.major, least.minor) >= DIRECT_TORQUE_SINCE


def _check_tool(s: UrRtdeSettings, file: str) -> None:
    """The tool's settings: sizes, and a payload within the model's rating."""
    key = "resource.settings"
    if s.payload_kg is not None and s.payload_kg > RATED_PAYLOAD_KG[s.model]:
        raise ConfigError(
            file, f"{key}.payload_kg",
            f"(={s.payload_kg:g}) exceeds the {s.model}'s rated payload ({RATED_PAYLOAD_KG[s.model]:g} kg)",
        )  # fmt: skip
    if s.payload_cog_m is not None and s.payload_kg is None:
        raise ConfigError(file, f"{key}.payload_cog_m", "needs payload_kg (the mass it belongs to)")
    for name, value, n in (("payload_cog_m", s.payload_cog_m, 3), ("tcp_m_rad", s.tcp_m_rad, 6)):
        if value is not None and len(value) != n:
            raise ConfigError(file, f"{key}.{name}", f"(={value!r}) must have {n} numbers")


def _check_io(s: UrRtdeSettings, file: str) -> None:
    """Each named input and output action: an identifier, on an I/O the controller has."""
    for table, parse in (("digital_inputs", lambda v: io_bit(v, "I")), ("digital_outputs", output_action)):
        for name, spec in (getattr(s, table) or {}).items():
            key = f"resource.settings.{table}.{name}"
            if not NAME.match(name) or name == "fault":
                raise ConfigError(file, key, "must be an identifier (letters, digits, _), not `fault`")
            try:
                parse(spec)
            except ValueError as e:
                raise ConfigError(file, key, f"(={spec!r}) {e}") from None


def _period_of(model: str) -> float:
    return 0.002 if model in E_SERIES else 0.008


class UrRtdeArm(PhysicalResource):
    Settings = UrRtdeSettings

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        s: UrRtdeSettings = config.backend_settings
        return (f"UR controller at {s.host}",)  # one RTDE control script per controller

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        s: UrRtdeSettings = config.backend_settings
        return ResourceDescription(
            backend="ur_rtde",
            joints=config.joint_names,
            modes=frozenset(
                {CommandMode.POSITION, CommandMode.VELOCITY}
                | ({CommandMode.TORQUE} if direct_torque(config) else set())
            ),
            mode_switch_needs_disable=False,
            position=MEASURED,
            velocity=MEASURED,
            torque=Quantity(Source.ESTIMATED, "the controller's target joint moments (RTDE target_moment)"),
            brakes=True,
            stop_categories=frozenset({1, 2}),
            read_time_s=0.0,  # the latest package, already received by ur_rtde's thread
            write_time_s=0.0002,  # one RTDE input package
            clock=ClockSource.DEVICE,
            device_period_s=_period_of(s.model),
            fault_reset=True,
            signals=SIGNALS,
            commands=COMMANDS,
            inputs=tuple(s.digital_inputs or {}),
            outputs=tuple(s.digital_outputs or {}),
        )

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> UrRtdeSettings:
        from orccadd.config.schema import load_dataclass

        s = load_dataclass(UrRtdeSettings, raw, file, "resource.settings")
        if len(cfg.joints) != 6:
            raise ConfigError(file, "joints", f"a UR arm has 6 joints, the config lists {len(cfg.joints)}")
        _check_tool(s, file)
        _check_io(s, file)
        try:
            parse_polyscope_version(s.min_version)
        except ValueError:
            raise ConfigError(
                file, "resource.settings.min_version", f"(={s.min_version!r}) is not a version like 5.4"
            ) from None
        return s

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        self.settings: UrRtdeSettings = config.backend_settings
        self.period_s = config.control_period_s
        self.link = RemoteLink(self.settings, self.period_s, self.name)
        self._last_stamp = -1.0
        self._last_new_s = 0.0  # tick time at which the last new package was seen
        self._comm_lost = ""
        self._controller_stopped = False  # the controller stopped the arm itself (its script too)
        self._off_by_us = False  # our category 1 stop powered the arm off: not a fault
        self._hold = np.zeros(self.dof)  # the command kept while waiting (position mode)
        self._cmd_v = np.zeros(self.dof)  # the servoJ targets' velocity (position mode)
        self._ramp = StopRamp(self.dof)
        self._zero = np.zeros(self.dof)  # the velocity held while waiting (and the extra torque)
        self._pin, self._data = model.model, model.new_data()  # the gravity the controller adds
        self._tau = np.zeros(self.dof)  # the torque sent: commanded minus gravity
        self._keep = TorqueHold(model, gravity=False)  # ticks without a torque command
        self._stop_t0 = 0.0  # tick time the safe stop began
        self.packets_missed = 0
        self._wrench, self._speed_scaling = self.signals["wrench"], self.signals["speed_scaling"]
        # the named inputs' bits in RTDE's digital input bits, in the description's order
        self._input_bits = [io_bit(v, "I") for v in (self.settings.digital_inputs or {}).values()]
        self._inputs_were = -1  # the named inputs' levels at the last read (-1: none read yet)
        self._rose = 0
        self._force_cmd, self._freedrive_cmd = self.commands[FORCE_MODE], self.commands[FREEDRIVE]
        self._behaving = ""  # the controller's behaviour a task runs: FORCE_MODE, FREEDRIVE or ""
        self._tool_cmd = self.commands[TOOL]
        self._task_tool: tuple[float, ...] | None = None  # the tool a task set (kept across resets)
        self._flags = 0  # the last read's status flags, repeated while a reset holds the links

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        self._connect()

    def _connect(self) -> None:
        self.link.connect()
        self._last_stamp = -1.0
        self._last_new_s = 0.0
        self._comm_lost = ""

    def _on_activate(self, mode: CommandMode) -> None:
        self._read_into(time.monotonic(), self.state)
        self._hold_here()

    def _hold_here(self) -> None:
        self._hold[:] = self.state.q_rad
        self._cmd_v[:] = 0.0
        self._keep.release()

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        self._hold_here()

    def _on_deactivate(self) -> None:
        if not self._comm_lost and not self.link.dead:
            with contextlib.suppress(ResourceError):  # the link gone: the controller's watchdog stops it
                self.link.call("control", "servoStop", self.config.safe_stop.deceleration_rad_s2)

    def _on_shutdown(self) -> None:
        self.link.shutdown()

    def _on_clear_stop(self) -> None:
        with self.link.lock:
            self._clear_stop_locked()

    def _clear_stop_locked(self) -> None:
        if self._off_by_us:  # our category 1 stop powered it off at rest (not the controller's stop:
            # `reset` has restarted its script already; a second restart raced the next commands)
            if not self.settings.power_on:
                raise ResourceError(f"{self.name}: powered off by the stop: power it on at the pendant")
            self.link.power_on()
            self.link.restart_script()
            self._restore_tool()
            self._off_by_us = False
        self._hold_here()

    def _on_reset_fault(self) -> None:
        with self.link.lock:
            self._reset_fault_locked()

    def _reset_fault_locked(self) -> None:
        if self._comm_lost:
            self._reconnect()
            return
        st = self.state
        latest = self.link.read()
        if self._off_by_us and latest is not None and latest.safety_mode == SafetyMode.NORMAL:
            return  # nothing but our own power-off: `clear_stop` powers it on
        cond = self.link.condition()
        if cond is None:
            return
        if cond.needs:
            raise ResourceError(f"{self.name}: {cond.what}: `reset` cannot clear it ({cond.needs})")
        if cond.unlockable:  # the controller allows it 5 s after the stop began, and says so
            self.link.unlock_protective_stop()
        self.link.restart_script()
        self._restore_tool()
        self.fault = None
        st.fault_code = 0

    def _reconnect(self) -> None:
        """After CommLost, with the arm safe-stopped: every link closed and opened again as at
        startup (the controller may have been restarted: model, version and period checked
        again), the state read afresh, and the stop's hold taken from where the arm now is."""
        self._connect()  # a new link process (the old one ended at the loss)
        self._flags = self._read_locked(time.monotonic(), self.state)
        if self._comm_lost:
            raise ResourceError(f"{self.fault_message}: reconnected, but no package has come")
        self._restore_tool()
        self._hold_here()
        self._begin_safe_stop()
        self.fault = None
        self.state.fault_code = 0

    # ---- the device's clock ---------------------------------------------------------------
    def wait_for_cycle(self, timeout_s: float) -> int:
        """Until the link process has sent a package with a new controller timestamp."""
        if self.link.lock.locked() or self._comm_lost:  # a reset replaces the link; or none
            time.sleep(timeout_s)
            return -1
        return self.link.wait_for_package(self._last_stamp, timeout_s)

    # ---- tick -----------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState) -> int:
        if not self.link.lock.acquire(blocking=False):
            return self._flags
        try:
            self._flags = self._read_locked(t_s, state)
        finally:
            self.link.lock.release()
        return self._flags

    def _read_locked(self, t_s: float, state: JointState) -> int:
        link = self.link
        if self._comm_lost:  # latched until `reset` starts a new link process
            return int(Status.COMM_LOST)
        pkg = link.read()
        if pkg is None or link.dead:
            self._lose(link.dead or "no RTDE package yet")
            return int(Status.COMM_LOST)
        connected, stamp = pkg.connected, pkg.stamp
        if stamp != self._last_stamp or not self._last_new_s:
            if self._last_stamp >= 0:
                self.packets_missed += max(0, round((stamp - self._last_stamp) / self.period_s) - 1)
            self._last_stamp, self._last_new_s = stamp, t_s
        silent = round((t_s - self._last_new_s) / self.period_s)
        if not connected:
            self._lose("the RTDE connection is closed")
        elif silent >= self.settings.stall_periods:
            self._lose(f"no RTDE package for {silent} periods (the stream stalled)")
        if self._comm_lost:  # latched until `reset` reconnects
            return int(Status.COMM_LOST)
        refused = link.take_refusal()
        if refused is not None and refused[1]:  # ur_rtde raised: its link is down
            self._lose(f"the RTDE connection is closed ({refused[1]})")
            return int(Status.COMM_LOST)
        state.q_rad[:] = pkg.q_rad
        state.dq_rad_s[:] = pkg.dq_rad_s
        state.tau_nm[:] = pkg.target_moment_nm
        if pkg.tcp_force:
            self._wrench[:] = pkg.tcp_force
        self._speed_scaling[0] = pkg.speed_scaling
        if self._input_bits:
            self._note_inputs(pkg.digital_inputs)
        robot_mode, safety_mode = pkg.robot_mode, pkg.safety_mode
        cond = pkg.condition()
        self._controller_stopped = cond is not None
        if refused is not None and self.fault is None:  # the type 3 says why
            why = cond.what if cond else "no stop reported yet"
            self._set_fault(FaultKind.DEVICE, f"the controller refused the command ({why})")
        if cond is None:
            return int(Status.FAULT) if refused is not None else 0
        if self._off_by_us and safety_mode == SafetyMode.NORMAL:
            return int(Status.TORQUE_OFF)  # as the stop left it, until `clear_stop` powers it on
        state.fault_code = safety_mode if safety_mode != SafetyMode.NORMAL else 100 + robot_mode
        # the controller's own code: its safety mode (UR's numbering), 0 when normal (the words
        # say the robot mode)
        code = safety_mode if safety_mode != SafetyMode.NORMAL else 0
        self._set_fault(FaultKind.DEVICE, cond.what, code=code)
        flags = int(Status.FAULT)
        if robot_mode != RobotMode.RUNNING:
            flags |= int(Status.TORQUE_OFF)
        return flags

    def _note_inputs(self, bits: int) -> None:
        levels = 0
        for i, b in enumerate(self._input_bits):
            levels |= (bits >> b & 1) << i
        if self._inputs_were >= 0:  # the first read sets the levels: an input already high is no edge
            self._rose |= levels & ~self._inputs_were
        self._inputs_were = levels

    def take_rising(self) -> int:
        rose, self._rose = self._rose, 0
        return rose

    def set_output(self, name: str) -> None:
        """The output action `name` (`digital_outputs`) through ur_rtde's I/O interface."""
        spec = (self.settings.digital_outputs or {}).get(name)
        if spec is None:
            super().set_output(name)
            return
        bit, on = output_action(spec)
        bank = "Standard" if bit < 8 else "Configurable" if bit < 16 else "Tool"
        index = bit if bit < 8 else bit - 8 if bit < 16 else bit - 16
        self.link.call("io", f"set{bank}DigitalOut", index, on)

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        if not self.link.lock.acquire(blocking=False):
            return 0
        try:
            if not self._control_ready():
                return int(Status.COMM_LOST)
            refused = self._tool(t_s)
            if refused:
                return refused
            behaviour = self._behaviour(t_s)
            return self._send(mode, command) if behaviour is None else behaviour
        except ResourceError as e:  # a call to the link process failed: it is gone
            self._lose(str(e))
            return int(Status.COMM_LOST)
        finally:
            self.link.lock.release()

    # ---- the tool a task sets ---------------------------------------------------------------
    def _tool(self, t_s: float) -> int:
        """The payload and TCP this tick's task asks for (`ur_tool`), set on the controller when
        they differ from what is set (a round trip to its script each: the task's first tick).
        Above the arm's rated payload, or refused by the controller: a type 3, nothing sent. 0:
        nothing asked, or set."""
        cmd = self._tool_cmd
        if cmd[0] != t_s:
            return 0
        wanted = tuple(cmd[1:].tolist())
        if wanted == self._task_tool:
            return 0
        model = self.settings.model
        rated = RATED_PAYLOAD_KG[model]
        if wanted[0] > rated:
            why = f"payload {wanted[0]:g} kg asked by the task exceeds the {model}'s rated {rated:g} kg"
            self._set_fault(FaultKind.COMMAND, why)
            return int(Status.FAULT)
        why = self._set_tool(wanted)
        if why:
            self._set_fault(FaultKind.DEVICE, why)
            return int(Status.FAULT)
        self._task_tool = wanted
        return 0

    def _set_tool(self, tool: tuple[float, ...]) -> str:
        """setPayload then setTcp; '' or what the controller refused."""
        mass, cog, tcp = tool[0], list(tool[1:4]), list(tool[4:10])
        if not self.link.call("control", "setPayload", mass, cog):
            return f"the controller refused payload {mass:g} kg (centre of gravity {cog} m)"
        if not self.link.call("control", "setTcp", tcp):
            return f"the controller refused the TCP {tcp}"
        return ""

    def _restore_tool(self) -> None:
        """After the script restarted (which sets the config's tool): the tool a task set, again."""
        if self._task_tool is not None:
            why = self._set_tool(self._task_tool)
            if why:
                raise ResourceError(f"{self.name}: after the restart, {why}")

    # ---- the controller's own behaviours (force mode, freedrive) --------------------------
    def _behaviour(self, t_s: float) -> int | None:
        """Force mode or freedrive where this tick's task asks for one (its module wrote the tick's
        time into the command): sent instead of the joint command, whose flags are returned;
        None: neither, and one that ran is ended first (the arm then held where it is). The
        caller has checked the link (`_control_ready`), once per tick."""
        if self._force_cmd[0] == t_s:
            return self._force_mode(self._force_cmd)
        if self._freedrive_cmd[0] == t_s:
            return self._freedrive(self._freedrive_cmd)
        if self._behaving:
            self._end_behaviour()
        return None

    def _force_mode(self, cmd: FloatArray) -> int:
        s = self.settings
        frame, selection, wrench = cmd[1:7], cmd[7:13], cmd[13:19]
        frame_type, limits = int(cmd[19]), cmd[20:26]
        force = float(np.linalg.norm(wrench[:3] * selection[:3]))
        speed = float(np.max(limits[:3] * selection[:3]))
        why = ""
        if force > s.force_mode_max_force_n:
            why = f"{force:.4g} N asked, above force_mode_max_force_n = {s.force_mode_max_force_n:g} N"
        elif speed > s.force_mode_max_speed_m_s:
            limit = s.force_mode_max_speed_m_s
            why = f"{speed:.4g} m/s allowed, above force_mode_max_speed_m_s = {limit:g} m/s"
        if why:
            self._set_fault(FaultKind.COMMAND, f"force mode refused: {why} ([resource.settings])")
            return int(Status.FAULT)
        if self._behaving == FREEDRIVE:
            self._end_behaviour()
        self._behaving = FORCE_MODE
        sent = self.link.send(
            "forceMode",
            frame.tolist(),
            [int(x) for x in selection],
            wrench.tolist(),
            frame_type,
            limits.tolist(),
        )
        return 0 if sent else int(Status.COMM_LOST)

    def _freedrive(self, cmd: FloatArray) -> int:
        if self._behaving != FREEDRIVE:
            if self._behaving == FORCE_MODE:
                self._end_behaviour()
            free, feature = [int(x) for x in cmd[1:7]], cmd[7:13].tolist()
            if not self.link.call("control", "freedriveMode", free, feature):
                self._set_fault(FaultKind.DEVICE, "the controller refused freedrive")
                return int(Status.FAULT)
            self._behaving = FREEDRIVE
        self.link.send("kickWatchdog")
        return 0

    def _end_behaviour(self) -> None:
        """The controller's behaviour ended (force_mode_stop, end_freedrive_mode: a round trip to
        its script, once); the joint stream then holds the arm where it is."""
        ending, self._behaving = self._behaving, ""
        self.link.call("control", "forceModeStop" if ending == FORCE_MODE else "endFreedriveMode")
        self._hold[:] = self.state.q_rad
        self._cmd_v[:] = 0.0

    def _lose(self, why: str) -> None:
        """CommLost, said as first seen (the type 3 reports the message of its tick). The link
        process is ended at once (a signal: tick-safe): left to a dead or vanished controller,
        ur_rtde's control interface reconnects from its own thread and then runs two receive
        threads on one connection, which has crashed the process it runs in; the controller's
        watchdog stops the script when our link closes. `reset` starts a new one."""
        if not self._comm_lost:
            self._comm_lost = why
            self._set_fault(FaultKind.COMM_LOST, why)
            self.link.close()

    def _control_ready(self) -> bool:
        """The link up and the controller's watchdog armed (`UrLink.arm_watchdog`)."""
        if self._comm_lost:
            return False
        pkg = self.link.state
        if self.link.dead or pkg is None or not pkg.connected:
            self._lose(self.link.dead or "the RTDE connection is closed")
            return False
        try:
            self.link.arm_watchdog(self.settings.watchdog_s)
        except ResourceError as e:
            self._lose(str(e))
            return False
        return True

    def _send(self, mode: CommandMode, command: FloatArray) -> int:
        """The joint command (the link checked by the caller, `_control_ready`)."""
        s = self.settings
        if mode is CommandMode.POSITION:
            np.subtract(command, self._hold, out=self._cmd_v)
            self._cmd_v /= self.period_s
            self._hold[:] = command
            q = command.tolist()
            sent = self.link.send("servoJ", q, 0.0, 0.0, self.period_s, s.lookahead_time_s, s.gain)
        elif mode is CommandMode.TORQUE:
            sent = self._direct_torque(command)
        else:
            sent = self.link.send("speedJ", command.tolist(), s.speedj_acceleration_rad_s2, self.period_s)
        if sent:
            return 0  # a refusal comes back and is taken by the next read
        self._lose(self.link.dead or "the UR link process is gone")
        return int(Status.COMM_LOST)

    def _direct_torque(self, tau_nm: FloatArray) -> bool:
        """Our torque command is the whole joint torque (a computed-torque law includes gravity);
        the controller adds its own gravity compensation to what `directTorque` sends, so gravity
        at the measured q is taken off first."""
        self._keep.release()
        gravity = pin.computeGeneralizedGravity(self._pin, self._data, self.state.q_rad)
        np.subtract(tau_nm, gravity, out=self._tau)
        return self.link.send("directTorque", self._tau.tolist(), NO_FRICTION_SCALE, NO_FRICTION_SCALE)

    def _keep_torque(self) -> None:
        """A torque tick without a command: the controller returns to position control unless
        `direct_torque` comes every cycle, and gravity alone would let a moving arm coast on. So
        the arm is held, in torque, where it was at the first such tick (`TorqueHold`, gravity
        left to the controller), within the joints' max torque."""
        self._keep.update(self.state, self._tau)
        tau_max = self.model.tau_max_nm
        np.clip(self._tau, -tau_max, tau_max, out=self._tau)
        self.link.send("directTorque", self._tau.tolist(), NO_FRICTION_SCALE, NO_FRICTION_SCALE)

    def _on_keep_alive(self, t_s: float) -> None:
        if self._comm_lost:  # nothing reaches the controller: its watchdog stops the script
            if self._stop_flags & Status.STOPPING and t_s - self._stop_t0 > self.config.safe_stop.timeout_s:
                self._mark_stopped(torque_off=False)
            return
        if not self.link.lock.acquire(blocking=False):
            return
        try:
            self._keep_alive_locked(t_s)
        except ResourceError as e:  # the link process gone under the stop's servoStop
            self._lose(str(e))
        finally:
            self.link.lock.release()

    def _keep_alive_locked(self, t_s: float) -> None:
        if not self._control_ready():
            return
        if not self._stop_flags and (self._tool(t_s) or self._behaviour(t_s) is not None):
            return  # a refused tool (a type 3 follows), or the controller's behaviour asked this tick
        if self._stop_flags & Status.STOPPING:
            self._ramp_step(t_s)
        elif self._stop_flags:  # at rest after the stop: no command, the watchdog still fed
            self.link.send("kickWatchdog")
        elif self.mode is CommandMode.TORQUE:
            self._keep_torque()
        else:
            self._send(self.mode, self._hold if self.mode is CommandMode.POSITION else self._zero)

    def _begin_safe_stop(self) -> None:
        if self._behaving:  # the controller's behaviour first: our ramp drives the joints
            try:
                self._end_behaviour()
            except ResourceError as e:
                self._lose(str(e))
        st = self.state
        if self.mode is CommandMode.POSITION:  # from the servoJ target and its velocity: the arm
            # lags it by the lookahead, and a target pulled back to it is a deceleration step
            self._ramp.start(self._hold.tolist(), self._cmd_v.tolist(), st.t_s)
        else:
            self._ramp.start(st.q_rad.tolist(), st.dq_rad_s.tolist(), st.t_s)
        self._stop_t0 = st.t_s

    def _ramp_step(self, t_s: float) -> None:
        """One period of the stop (`StopRamp`), through the active mode's stream. When the
        controller has stopped the arm itself (a protective stop, its script halted), it is only
        watched."""
        at_rest = float(np.abs(self.state.dq_rad_s).max()) < AT_REST_RAD_S
        if self._controller_stopped:
            if at_rest:
                self._mark_stopped(self.config.safe_stop.category == 1)
            return
        ramp, s, link = self._ramp, self.settings, self.link
        decel = self.config.safe_stop.deceleration_rad_s2
        ramp.step(t_s, decel)
        if self.mode is CommandMode.POSITION:
            link.send("servoJ", ramp.q_rad, 0.0, 0.0, self.period_s, s.lookahead_time_s, s.gain)
        else:  # velocity, and torque: the ramp's speeds from the measured state (a servoJ
            # started at speed would brake the arm at once: its target is not ahead of the arm)
            link.send("speedJ", ramp.dq_rad_s, decel, self.period_s)
        if ramp.done and at_rest:
            self._at_rest()

    def _at_rest(self) -> None:
        decel = self.config.safe_stop.deceleration_rad_s2
        self.link.call("control", "servoStop" if self.mode is CommandMode.POSITION else "speedStop", decel)
        torque_off = self.config.safe_stop.category == 1
        if torque_off:
            self.link.power_off()
            self._off_by_us = True
        self._mark_stopped(torque_off)

    # ---- diagnostics ----------------------------------------------------------------------
    def _details(self) -> dict[str, float | int | str]:
        return {
            **super()._details(),
            "controller": f"{self.link.robot_model} {self.link.version}" if self.link.version else "",
            "packets_missed": self.packets_missed,
            "comm": self._comm_lost or "ok",
            "speed_scaling": round(float(self._speed_scaling[0]), 3),
            "tcp_wrench_n_nm": " ".join(f"{x:.2f}" for x in self._wrench),
            **self._measured(),
        }

    def _measured(self) -> dict[str, float | int | str]:
        return {} if self._comm_lost else self.link.measured()
