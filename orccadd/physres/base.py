"""The Physical Resource: the robot as a control law sees it.

One ABC for every backend (simulated arm, CiA 402 drives, Dynamixel servos, UR over RTDE). The
base class does the shared work, like python-can's `BusABC`: the lifecycle, limit enforcement
on every command, measured-limit checks and the status flags; a backend overrides a few hooks
(`_on_configure`, `_on_activate`, `_read_into`, `_write_command`, `_begin_safe_stop`, ...).

Tick methods (`read`, `write`, `safe_stop`) allocate no arrays and raise nothing on the
normal path: they report through `Status` flags. Lifecycle methods are not for a tick.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from math import isfinite
from operator import add, sub
from time import monotonic_ns
from typing import Any, ClassVar

import numpy as np

from orccadd.config.robot import RobotConfig
from orccadd.errors import LifecycleError, ResourceError
from orccadd.fault import Fault, FaultKind
from orccadd.kinematics import ToolWorkspace
from orccadd.model import RobotModel
from orccadd.physres.description import ResourceDescription
from orccadd.physres.guard import VelocityGuard
from orccadd.state import FloatArray, JointState
from orccadd.types import CMD_CLAMPED, LIMIT_VIOLATION, CommandMode, Lifecycle, Status
from orccadd.vec import clamped, outside, within
from orccadd.wire.schema import status_names

# the modes a tick compares with, as module globals (an IntEnum member's lookup costs ~0.1 µs)
TORQUE, VELOCITY, POSITION = CommandMode.TORQUE, CommandMode.VELOCITY, CommandMode.POSITION

# Lifecycle transitions allowed: (from, method) -> to.
TRANSITIONS: dict[tuple[Lifecycle, str], Lifecycle] = {
    (Lifecycle.UNCONFIGURED, "configure"): Lifecycle.INACTIVE,
    (Lifecycle.INACTIVE, "activate"): Lifecycle.ACTIVE,
    (Lifecycle.ACTIVE, "deactivate"): Lifecycle.INACTIVE,
    (Lifecycle.UNCONFIGURED, "shutdown"): Lifecycle.FINALIZED,
    (Lifecycle.INACTIVE, "shutdown"): Lifecycle.FINALIZED,
    (Lifecycle.ACTIVE, "shutdown"): Lifecycle.FINALIZED,
}


@dataclass(frozen=True)
class Diagnostics:
    """A snapshot of a resource for `status` and `describe` (not for a tick)."""

    backend: str
    lifecycle: str
    mode: str
    status: tuple[str, ...]
    fault_message: str
    fault_code: int
    helper_pid: int  # a process the resource runs (the simulated plant), 0 if none
    details: dict[str, float | int | str]  # backend counters and names (frames lost, channel, ...)


class PhysicalResource(ABC):
    """Base of every backend. Subclasses implement `describe` and the hooks, and set `Settings`."""

    Settings: ClassVar[type[Any]]

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        self.config = config
        self.model = model
        self.description = type(self).describe(config)
        self.supported_modes = self.description.modes
        self.name = config.resource.name
        self.dof = model.dof
        self.lifecycle = Lifecycle.UNCONFIGURED
        self.mode = CommandMode.TORQUE
        self.state = JointState(self.dof)
        # the description's other signals, preallocated: `read` fills them in place
        self.signals: dict[str, FloatArray] = {g.name: np.zeros(g.size) for g in self.description.signals}
        # and the commands beyond the joint command (element 0: the tick that wrote it, NaN: none)
        self.commands: dict[str, FloatArray] = {
            g.name: np.full(g.size, np.nan) for g in self.description.commands
        }
        self.fault: Fault | None = None  # what the device or the limits reported last (None: nothing)
        self._cmd: FloatArray = np.zeros(self.dof)
        self._last_pos_cmd: FloatArray = np.zeros(self.dof)
        # limits as lists: the tick checks them with list builtins (see orccadd.vec)
        tol_q = config.limits.position_tolerance_rad
        dq_max = model.v_max_rad_s * config.limits.velocity_tolerance
        self._limit_lo: list[float] = [*(model.q_min_rad - tol_q).tolist(), *(-dq_max).tolist()]  # on q_dq
        self._limit_hi: list[float] = [*(model.q_max_rad + tol_q).tolist(), *dq_max.tolist()]
        # finite limits (the usual): `within` them says finite too, no finiteness test needed
        self._limits_finite = all(map(isfinite, self._limit_lo + self._limit_hi))
        self._tau_lo, self._tau_hi = (-model.tau_max_nm).tolist(), model.tau_max_nm.tolist()
        self._v_lo, self._v_hi = (-model.v_max_rad_s).tolist(), model.v_max_rad_s.tolist()
        self._q_lo, self._q_hi = model.q_min_rad.tolist(), model.q_max_rad.tolist()
        step_max = model.v_max_rad_s * config.control_period_s * config.limits.velocity_tolerance
        self._step_max: list[float] = step_max.tolist()
        self._stop_flags = 0
        self._output_fault = ""  # an output action that failed (`output_failed`), until a reset
        # the tool's workspace ([workspace]), if any: measured beyond it by more than its tolerance,
        # or a position command taking the tool further out of it, is a LIMIT_VIOLATION
        self._workspace = ToolWorkspace.of(model)
        self._workspace_tolerance_m = config.workspace.tolerance_m
        # how far out it may be measured: the tolerance, or where a reset found it plus the
        # tolerance (the arm stopped outside may be brought back, not further out), lowered as
        # it comes back in
        self._workspace_allowed_m = self._workspace_tolerance_m
        self._last_cmd_excess_m = 0.0  # how far out the last position command put the tool
        # torque commands that would carry a joint past max_velocity are cut before the device
        torque = CommandMode.TORQUE in self.supported_modes
        self._velocity_guard = VelocityGuard(model, config.control_period_s) if torque else None
        self.clamp_count = 0
        self.rejected_count = 0  # commands with a NaN or an infinity, never sent
        self._prepared_modes: set[CommandMode] = set()  # `prepare_mode_switch` done
        self._read_at_ns = 0  # when a tick last read the resource (CLOCK_MONOTONIC)
        self._ticking_within_ns = int((3 * config.control_period_s + 0.05) * 1e9)

    # ---- declaration and settings ---------------------------------------------------------
    @classmethod
    @abstractmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        """What this backend can do with `config` (checked settings in `config.backend_settings`),
        before anything is opened: see `orccadd.physres.description`."""

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        """What this resource holds alone (a serial port, a CAN node on its bus, a controller's
        address), in words: a station refuses two resources that claim the same. Default: none."""
        return ()

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> Any:
        """Check `[resource.settings]` strictly into `cls.Settings`. Override to cross-check."""
        from orccadd.config.schema import load_dataclass

        return load_dataclass(cls.Settings, raw, file, "resource.settings")

    # ---- lifecycle (not for a tick) -------------------------------------------------------
    def _transition(self, method: str) -> None:
        nxt = TRANSITIONS.get((self.lifecycle, method))
        if nxt is None:
            raise LifecycleError(
                f"resource {self.name!r}: cannot {method} while {self.lifecycle.name.lower()}"
            )
        self.lifecycle = nxt

    def configure(self) -> None:
        """Open the bus/connection and check the device can do what the config asks."""
        if self.lifecycle is not Lifecycle.UNCONFIGURED:
            self._transition("configure")
        self._on_configure()
        self._transition("configure")

    def activate(self, mode: CommandMode) -> None:
        """Enable the motors in `mode`, holding the current position."""
        if mode not in self.supported_modes:
            allowed = ", ".join(m.name.lower() for m in sorted(self.supported_modes))
            raise ResourceError(
                f"resource {self.name!r} ({type(self).__name__}) cannot command "
                f"{mode.name.lower()} (supported: {allowed})"
            )
        if self.lifecycle is not Lifecycle.INACTIVE:
            self._transition("activate")
        self.mode = mode
        self._stop_flags = 0
        self._on_activate(mode)
        self.state.status = 0
        self._hold_position_command()
        self._transition("activate")

    def prepare_mode_switch(self, mode: CommandMode) -> None:
        """A mode switch's first phase, outside the tick (when a mission's tasks are built): check
        that the device can take `mode` while enabled and prepare what the switch sends, so that
        `perform_mode_switch` only sends it (ros2_control's `prepare_command_mode_switch`).
        `ResourceError` if it cannot; once per mode."""
        if mode not in self.supported_modes:
            allowed = ", ".join(m.name.lower() for m in sorted(self.supported_modes))
            raise ResourceError(
                f"resource {self.name!r} cannot command {mode.name.lower()} (supported: {allowed})"
            )
        if mode not in self._prepared_modes:
            self._on_prepare_mode_switch(mode)
            self._prepared_modes.add(mode)

    def perform_mode_switch(self, mode: CommandMode) -> None:
        """A mode switch's second phase, in the tick (between two tasks' commands): the device
        takes the prepared `mode` (ros2_control's `perform_command_mode_switch`)."""
        if self.lifecycle is not Lifecycle.ACTIVE:
            raise LifecycleError(f"resource {self.name!r}: a mode switch needs an active resource")
        if mode not in self._prepared_modes:
            raise LifecycleError(f"resource {self.name!r}: switch to {mode.name.lower()} mode not prepared")
        self._on_perform_mode_switch(mode)
        self.mode = mode
        self._hold_position_command()

    def switch_mode(self, mode: CommandMode) -> None:
        """Both phases at once, for a caller outside the tick."""
        self.prepare_mode_switch(mode)
        self.perform_mode_switch(mode)

    def deactivate(self) -> None:
        """Disable the motors (brakes on where the device has them)."""
        self._transition("deactivate")
        self._on_deactivate()

    def shutdown(self) -> None:
        """Release the hardware. Safe to call in any state but finalized."""
        if self.lifecycle is Lifecycle.ACTIVE:
            self._on_deactivate()
        self._transition("shutdown")
        self._on_shutdown()

    def clear_stop(self) -> None:
        """Leave the stopped state after a safe stop, if no fault remains (not for a tick)."""
        if self.state.status & (Status.FAULT | Status.COMM_LOST):
            raise ResourceError(
                f"resource {self.name!r}: cannot clear the stop while faulted ({self.fault_message})"
            )
        self._on_clear_stop()  # the device first; commands stay ignored until it confirmed
        self._hold_position_command()
        self._stop_flags = 0

    # ---- optional interfaces (declared in the description; not for a tick) ------------------
    def reset_fault(self) -> None:
        """Ask the device to leave its fault state (CiA 402 fault reset, servo reboot, ...); the
        following reads show whether it did. `ResourceError` if the backend declares none."""
        if not self.description.fault_reset:
            raise ResourceError(f"resource {self.name!r} ({self.description.backend}) cannot reset a fault")
        self._on_reset_fault()

    def take_rising(self) -> int:
        """The named digital inputs (`description.inputs`, bit i for the i-th) that rose since
        the last call (tick-safe; the backend notes them as it reads). Default: none."""
        return 0

    def set_output(self, name: str) -> None:
        """Perform the output action `name` (`description.outputs`: a digital output set or
        cleared). Not for a tick; `ResourceError` if it cannot."""
        raise ResourceError(f"resource {self.name!r} ({self.description.backend}) has no output {name!r}")

    def output_failed(self, name: str, why: str) -> None:
        """The output action `name` failed (its unit's output thread says so): a fault of this
        resource from its next read on (FAULT: its task's ResourceFault), until a reset clears
        it (`clear_output_fault`)."""
        self._output_fault = f"output {name} not performed: {why}"

    def clear_output_fault(self) -> None:
        """A reset: an output action's failure is forgotten (the device's own faults are not)."""
        self._output_fault = ""

    def inject_fault(self, kind: str, message: str) -> None:
        """Make the device report a fault of `kind` (tests, commissioning). `ResourceError` if the
        backend does not declare that kind."""
        kinds = self.description.fault_injection
        if kind not in kinds:
            offered = ", ".join(kinds) or "none"
            raise ResourceError(f"resource {self.name!r} cannot inject a {kind!r} fault (kinds: {offered})")
        self._on_inject_fault(kind, message)

    def diagnostics(self) -> Diagnostics:
        """A typed snapshot of the resource's state, fault and counters."""
        return Diagnostics(
            backend=self.description.backend,
            lifecycle=self.lifecycle.name.lower(),
            mode=self.mode.name.lower(),
            status=tuple(status_names(self.state.status)),
            fault_message=self.fault_message,
            fault_code=self.state.fault_code,
            helper_pid=self.helper_pid(),
            details=self._details(),
        )

    def wait_for_cycle(self, timeout_s: float) -> int:
        """Device-paced resources: block until the device's next cycle; its arrival time
        (CLOCK_MONOTONIC ns), or -1 after `timeout_s`. Loop-paced resources never get asked."""
        raise ResourceError(f"resource {self.name!r} is paced by the loop, not by its device")

    # ---- tick methods ---------------------------------------------------------------------
    def read(self, t_s: float) -> JointState:
        """Measure the state at time `t_s` (tick). Sets LIMIT_VIOLATION if outside limits."""
        st = self.state
        self._read_at_ns = monotonic_ns()
        st.status = self._read_into(t_s, st) | self._stop_flags
        st.t_s = t_s
        if self._output_fault:
            st.status |= Status.FAULT
            self._set_fault(FaultKind.DEVICE, self._output_fault)
        q_dq = st.q_dq.tolist()
        lo, hi = self._limit_lo, self._limit_hi
        if self._limits_finite:
            beyond = not within(q_dq, lo, hi)  # a NaN or an infinity too
        else:
            beyond = outside(q_dq, lo, hi) or not all(map(isfinite, q_dq))
        if beyond:
            st.status |= LIMIT_VIOLATION
            self.fault = self._beyond(FaultKind.LIMIT, "measured", q_dq, lo, hi)
        ws = self._workspace
        if ws is not None:
            excess = ws.excess_m(st.q_rad)
            if excess > self._workspace_allowed_m:
                st.status |= LIMIT_VIOLATION
                self.fault = Fault(FaultKind.LIMIT, self.name, f"measured {ws.describe_outside()}")
            elif excess + self._workspace_tolerance_m < self._workspace_allowed_m:  # coming back in
                self._workspace_allowed_m = max(
                    self._workspace_tolerance_m, excess + self._workspace_tolerance_m
                )
        return st

    @property
    def loop_ticking(self) -> bool:
        """A control loop ticks this resource (it read it within the last three periods and
        50 ms): lifecycle work on another thread (enable, reset) leaves the cyclic exchange to the
        ticks and waits for what they show, instead of running cycles of its own."""
        return monotonic_ns() - self._read_at_ns < self._ticking_within_ns

    @property
    def fault_message(self) -> str:
        """The last fault in words, with the resource's name ("" when none)."""
        return "" if self.fault is None else str(self.fault)

    def _set_fault(self, kind: FaultKind, text: str, joint: str = "", code: int = 0) -> None:
        """Record what the device reports (tick-safe: a new value only when it changes)."""
        f = self.fault
        if f is None or f.text != text or f.kind is not kind or f.joint != joint or f.code != code:
            self.fault = Fault(kind, self.name, text, joint, code)

    def _beyond(
        self, kind: FaultKind, what: str, values: list[float], lo: list[float], hi: list[float]
    ) -> Fault:
        """Which joint, quantity, value and limit a LIMIT_VIOLATION is about (the rare path of a
        tick: the words a type 3 reports). `values` per joint, positions then velocities when
        twice as long as the joints."""
        units = ("rad", "rad/s", "N.m")
        kinds = ("position", "velocity") if len(values) == 2 * self.dof else (self.mode.name.lower(),)
        for i, (v, a, b) in enumerate(zip(values, lo, hi, strict=True)):
            if not a <= v <= b:  # NaN too
                quantity = kinds[i // self.dof]
                unit = units[("position", "velocity", "torque").index(quantity)]
                joint = self.model.joint_names[i % self.dof]
                text = f"{what} {quantity} of {joint} {v:.4g} {unit} outside [{a:.4g}, {b:.4g}]"
                return Fault(kind, self.name, text, joint)
        return Fault(kind, self.name, f"{what} values not finite")

    def write(self, t_s: float, command: FloatArray) -> int:
        """Send one command in the active mode (tick). Returns the `Status` flags.

        Torques are clamped to max_torque_nm, and cut where they would carry a joint past its
        max_velocity within two periods (`guard.VelocityGuard`; CMD_CLAMPED). Position and velocity commands
        outside the limits, or position steps faster than max_velocity, are clamped and also
        flagged LIMIT_VIOLATION (a type 3 exception for the task). A command with a NaN or an
        infinity is not sent and flagged LIMIT_VIOLATION. During a safe stop the command is
        ignored.
        """
        if self._stop_flags:
            self._on_keep_alive(t_s)
            return self._stop_flags | self.state.status
        wanted = command.tolist()
        if not all(map(isfinite, wanted)):
            self.rejected_count += 1
            self.fault = Fault(
                FaultKind.COMMAND, self.name, f"a command with a NaN or an infinity was not sent: {wanted}"
            )
            return LIMIT_VIOLATION
        mode = self.mode
        cmd = self._cmd
        if mode is TORQUE:  # saturated, then cut where it would outrun a joint: never a violation
            lo, hi = self._tau_lo, self._tau_hi
            changed = not within(wanted, lo, hi)  # (cheaper than clamping: the usual case)
            cmd[:] = clamped(wanted, lo, hi) if changed else command  # (an array copies faster)
            guard = self._velocity_guard
            if guard is not None:
                st = self.state
                cut = guard.limit(st.q_rad, st.dq_rad_s, cmd)  # the saturated torques' dynamics
                if cut is not None:
                    cmd[:] = cut
                    changed = cut != wanted
            if changed:
                self.clamp_count += 1
                return CMD_CLAMPED | self._write_command(t_s, mode, cmd)
            return self._write_command(t_s, mode, cmd)
        if mode is VELOCITY:
            sent = clamped(wanted, self._v_lo, self._v_hi)
        else:  # position: within the joint range, and no faster than max_velocity from the last one
            sent = clamped(wanted, self._q_lo, self._q_hi)
            last = self._last_pos_cmd.tolist()
            step = self._step_max
            sent = clamped(sent, list(map(sub, last, step)), list(map(add, last, step)))
        flags = 0
        if sent != wanted:  # a position or a velocity beyond the limits: a violation
            flags = CMD_CLAMPED | LIMIT_VIOLATION
            self.clamp_count += 1
            self.fault = self._beyond(
                FaultKind.LIMIT, "command clamped: commanded", wanted, *self._command_bounds(mode)
            )
        ws = self._workspace
        if ws is not None and mode is POSITION:
            excess = ws.excess_m(sent)
            if excess > 0.0 and excess > self._last_cmd_excess_m + 1e-9:  # out, or further out
                flags |= LIMIT_VIOLATION
                self.fault = Fault(FaultKind.LIMIT, self.name, f"command not sent: {ws.describe_outside()}")
                sent = self._last_pos_cmd.tolist()  # held: the tool goes no further out
            else:
                self._last_cmd_excess_m = excess
        cmd[:] = sent
        if mode is POSITION:
            self._last_pos_cmd[:] = cmd
        return flags | self._write_command(t_s, mode, cmd)

    def _hold_position_command(self) -> None:
        """The next position command is checked from the measured position (a mode switch, an
        enable, a reset): its step, and how far out of the workspace it may start; the measured
        tool may be that far out, plus the tolerance, until it comes back in."""
        self._last_pos_cmd[:] = self.state.q_rad
        ws = self._workspace
        self._last_cmd_excess_m = ws.excess_m(self.state.q_rad) if ws is not None else 0.0
        self._workspace_allowed_m = self._workspace_tolerance_m + self._last_cmd_excess_m

    def _command_bounds(self, mode: CommandMode) -> tuple[list[float], list[float]]:
        """The bounds a command of `mode` was held to in this tick (position: the range and the
        step the maximum velocity allows from the last command)."""
        if mode is CommandMode.VELOCITY:
            return self._v_lo, self._v_hi
        last, step = self._last_pos_cmd.tolist(), self._step_max
        lo = [max(q, p - s) for q, p, s in zip(self._q_lo, last, step, strict=True)]
        hi = [min(q, p + s) for q, p, s in zip(self._q_hi, last, step, strict=True)]
        return lo, hi

    def keep_alive(self, t_s: float) -> None:
        """A tick without a new command (the task waits for its preconditions, is stopped, or
        none is active): keep the device fed with its holding command, as its watchdogs expect
        (tick-safe). The control loop calls either `write` or this once per tick, after `read`."""
        self._on_keep_alive(t_s)

    def safe_stop(self) -> None:
        """Bring the arm to rest by the configured stop category (tick-safe, idempotent)."""
        if self._stop_flags:
            return
        self._stop_flags = int(Status.STOPPING)
        self._begin_safe_stop()

    def _mark_stopped(self, torque_off: bool) -> None:
        """Backends call this when the safe stop has brought the arm to rest."""
        self._stop_flags = int(Status.STOPPED | (Status.TORQUE_OFF if torque_off else 0))

    @property
    def last_command(self) -> FloatArray:
        """The last command sent to the device (after the limits), in `mode`; read-only."""
        return self._cmd

    @property
    def stopping_or_stopped(self) -> bool:
        return bool(self._stop_flags)

    # ---- backend hooks --------------------------------------------------------------------
    @abstractmethod
    def _on_configure(self) -> None: ...

    @abstractmethod
    def _on_activate(self, mode: CommandMode) -> None:
        """Enable the device; leave the current measured position in `self.state.q_rad`
        (the position-mode rate limit starts from it)."""

    def _on_prepare_mode_switch(self, mode: CommandMode) -> None:
        """Check and prepare a switch to `mode` (not for a tick); default: nothing to prepare."""

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        """Change the device's mode while enabled, as prepared (tick); default: nothing to do."""

    @abstractmethod
    def _on_deactivate(self) -> None: ...

    @abstractmethod
    def _on_shutdown(self) -> None: ...

    def _on_clear_stop(self) -> None:
        """Re-enable after a safe stop; default: nothing to do."""

    def _on_keep_alive(self, t_s: float) -> None:
        """Send what keeps the device content without a new command; default: nothing."""

    def _on_reset_fault(self) -> None:
        """Backends that declare `fault_reset` implement this."""
        raise NotImplementedError

    def _on_inject_fault(self, kind: str, message: str) -> None:
        """Backends that declare `fault_injection` kinds implement this."""
        raise NotImplementedError

    def helper_pid(self) -> int:
        """A process this resource runs (the simulated plant), 0 if none (not for a tick)."""
        return 0

    def _details(self) -> dict[str, float | int | str]:
        guard = self._velocity_guard
        return {
            "clamped_commands": self.clamp_count,
            "rejected_commands": self.rejected_count,
            "velocity_guard_cuts": guard.cut_count if guard is not None else 0,
        }

    @abstractmethod
    def _read_into(self, t_s: float, state: JointState) -> int:
        """Fill `state` in place; return device status flags (FAULT, COMM_LOST ...)."""

    @abstractmethod
    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        """Send an already limited command; return device status flags."""

    @abstractmethod
    def _begin_safe_stop(self) -> None:
        """Start the device's own stop (quick stop, protective stop, controlled brake)."""
