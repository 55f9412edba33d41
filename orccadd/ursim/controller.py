"""The simulated controller: one cycle every 2 ms (e-Series; 8 ms CB3) that runs the program,
generates the target trajectory, checks it against the limits, drives the arm and publishes
the state to the RTDE clients.

Everything that changes the controller (dashboard commands, an uploaded program, RTDE inputs,
injected faults) does so under `lock`, which the cycle holds while it runs: each of them is
seen whole, between two cycles.

Safety, as a UR controller does it (stop categories of IEC 60204-1):
- protective stop: a target outside the joint range, faster than a joint's speed limit or, for
  servoj, accelerating harder than its acceleration limit (or an injected one, or
  `protective_stop()`): the arm stops on its trajectory at the joint acceleration limits and
  stays powered (category 2), the program pauses; "unlock protective stop" is accepted
  `unlock_delay_s` after it (5 s on UR controllers);
- emergency stop: stop at the limits, then power off (category 1); the program stops;
- power off: the brakes at once (category 0); the program stops;
- tool force limit: an external force on the tool above the safety configuration's limit
  (150 N, e-Series default) is a protective stop, as a collision is.

Each cycle also reads the flange's force/torque sensor (`force_control.ForceControl`: the
world's wrench on the tool, `world.World`) and moves the speed scaling towards the speed
slider (`speed_scaling.SpeedScaling`), which the planned motions run at.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from orccadd.state import FloatArray
from orccadd.ursim.arm import UrArm
from orccadd.ursim.control_script import Program
from orccadd.ursim.export import export_state
from orccadd.ursim.force_control import ForceControl
from orccadd.ursim.force_mode import TOOL_FORCE_LIMIT_N
from orccadd.ursim.motion import DirectTorque, Hold, Motion, StopJ, Target
from orccadd.ursim.robot_state import FieldTable, RobotState
from orccadd.ursim.series import Series
from orccadd.ursim.speed_scaling import SpeedScaling
from orccadd.ursim.states import (
    BOOT_S,
    POWER_TRANSITIONS,
    RELEASE_S,
    PowerEvent,
    RobotMode,
    RuntimeState,
    SafetyMode,
)

log = logging.getLogger("orccadd.ursim")

ESTOPPED = (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP)
HISTORY_CYCLES = 1000  # get_actual_joint_positions_history reaches this far back
STEADY_RAD_S = 1e-3
RATED_PAYLOAD_KG = 5.0  # UR5e


class UrController:
    """The controller's state and its cycle (`step`), shared by every server under `lock`."""

    def __init__(self, arm: UrArm, series: Series, unlock_delay_s: float, boot_running: bool) -> None:
        self.arm = arm
        self.series = series
        self.period_s = 1.0 / series.rate_hz
        self.unlock_delay_s = unlock_delay_s
        self.boot_running = boot_running
        self.lock = threading.RLock()
        self.clock: Callable[[], float] = time.monotonic  # the cycle's time base (tests: simulated)
        self.state = RobotState()
        self.fields = FieldTable(self.state)
        self.v_max_rad_s = arm.v_max_rad_s
        self.a_max_rad_s2 = arm.a_max_rad_s2
        self.target = Target(arm.dof)
        self.torque = DirectTorque(arm.dof)  # the one direct torque motion, set every cycle
        self._safe_target = Target(arm.dof)
        self.world = arm.world  # what the tool touches (the control channel sets it)
        self.forces = ForceControl(arm, self.state)
        self.speed = SpeedScaling()
        self.subscribers: list[Callable[[int], None]] = []  # RTDE sessions, called every cycle
        self.input_owner: dict[str, object] = {}  # input field -> the RTDE session writing it
        self._t0_s: float | None = None  # the first cycle's time: the controller's time 0
        self._now_s = 0.0  # the controller's time at its last cycle
        self._last_t_s: float | None = None
        self.reset()

    def reset(self) -> None:
        """The state after the controller boots (also after an injected restart)."""
        with self.lock:
            self._t0_s = None  # the timestamp restarts from 0
            self.robot_mode = RobotMode.POWER_OFF
            self.safety_mode = SafetyMode.NORMAL
            self.runtime_state = RuntimeState.STOPPED
            self.program: Program | None = None
            self.program_name = ""
            self.motion: Motion = Hold()
            self.motion_done = True
            self.protective_stop_s = 0.0
            self.stop_reason = ""
            self.power_off_when_stopped = False
            self._power_step_at_s: float | None = None  # when a timed power step completes
            self._release_pending = False
            self.watchdog: tuple[str, float] | None = None  # (register, min frequency)
            self._watch_last_s = 0.0
            self.history: deque[FloatArray] = deque(maxlen=HISTORY_CYCLES)
            self.cycles = 0
            self.protective_stops = 0
            self._reset_counters()
            self.state.in_int[:] = [0] * len(self.state.in_int)
            self.state.out_int[:] = [0] * len(self.state.out_int)
            self.state.in_double[:] = [0.0] * len(self.state.in_double)
            self.state.out_double[:] = [0.0] * len(self.state.out_double)
            self.state.digital_output_bits = 0
            self.set_payload(0.0, np.zeros(3))
            self.state.payload_cog[:] = 0.0
            self.forces.reset()
            self.speed.reset()
            self.arm.engage_brakes()
            self.target.hold(self.arm.q_rad)
            if self.boot_running:
                self.robot_mode = RobotMode.RUNNING
                self.arm.release_brakes()

    def now_s(self) -> float:
        """The controller's time (s since its first cycle) at its last cycle: every timing
        (power steps, unlock delay, watchdog, `timestamp`) follows the cycle's clock."""
        return self._now_s

    def clock_origin_s(self) -> float | None:
        """The CLOCK_MONOTONIC time (s) of the controller's time 0 (None before its first
        cycle): a package's `timestamp` + this = the scheduled start of the cycle that made it."""
        return self._t0_s

    # ---- power (dashboard) ----------------------------------------------------------------
    def power_event(self, event: PowerEvent) -> None:
        """Move the robot mode by the power table; timed steps complete in later cycles. While
        an emergency stop is engaged the arm cannot be powered."""
        nxt = POWER_TRANSITIONS.get((self.robot_mode, event))
        if nxt is None or (nxt is not RobotMode.POWER_OFF and self.safety_mode in ESTOPPED):
            return
        if event is PowerEvent.BRAKE_RELEASE:
            self._release_pending = True
        now = self.now_s()
        if nxt is RobotMode.POWER_OFF:
            self._power_off()
            return
        if nxt is RobotMode.POWER_ON and self.robot_mode is not RobotMode.POWER_ON:
            self._power_step_at_s = now + BOOT_S  # (already booting: its end stays where it was)
        elif nxt is RobotMode.IDLE and self._release_pending:
            self._power_step_at_s = now + RELEASE_S
        elif nxt is RobotMode.RUNNING:
            self.arm.release_brakes()
            self.target.hold(self.arm.q_rad)
            self._release_pending = False
            self._power_step_at_s = None
        self.robot_mode = nxt

    def _advance_power(self, now_s: float) -> None:
        if self._power_step_at_s is None or now_s < self._power_step_at_s:
            return
        self._power_step_at_s = None
        event = PowerEvent.BOOTED if self.robot_mode is RobotMode.POWER_ON else PowerEvent.RELEASED
        self.power_event(event)

    def _power_off(self) -> None:
        self.stop_program("power off")
        self.arm.engage_brakes()
        self.robot_mode = RobotMode.POWER_OFF
        self._power_step_at_s = None
        self._release_pending = False
        self.power_off_when_stopped = False
        self.motion, self.motion_done = Hold(), True
        self.target.hold(self.arm.q_rad)

    # ---- programs -------------------------------------------------------------------------
    def can_run_program(self) -> str:
        """Why a program cannot start now ('' if it can)."""
        if self.robot_mode is not RobotMode.RUNNING:
            return f"the robot is not running (robot mode {self.robot_mode.name})"
        if self.safety_mode is not SafetyMode.NORMAL:
            return f"safety mode is {self.safety_mode.name}"
        return ""

    def start_program(self, program: Program, name: str) -> bool:
        """Replace the running program by `program` (a program sent to a script port)."""
        if self.program is not None:
            self.stop_program(f"replaced by {name}")
        why = self.can_run_program()
        if why:
            log.warning("program %s not started: %s", name, why)
            return False
        self.program, self.program_name = program, name
        self.runtime_state = RuntimeState.PLAYING
        self.watchdog = None
        log.info("program %s started", name)
        return True

    def stop_program(self, why: str) -> None:
        if self.program is None and self.runtime_state is RuntimeState.STOPPED:
            return
        log.info("program %s stopped: %s", self.program_name or "?", why)
        self.program = None
        self.runtime_state = RuntimeState.STOPPED
        self.watchdog = None
        self._stop_motion()

    def pause_program(self, why: str) -> None:
        if self.runtime_state is RuntimeState.PLAYING:
            log.info("program %s paused: %s", self.program_name, why)
            self.runtime_state = RuntimeState.PAUSED
            self._stop_motion()

    def resume_program(self) -> bool:
        if self.runtime_state is not RuntimeState.PAUSED or self.program is None or self.can_run_program():
            return False
        self.runtime_state = RuntimeState.PLAYING
        return True

    def runtime_error(self, message: str) -> None:
        log.error("program %s: runtime error: %s", self.program_name, message)
        self.stop_program(f"runtime error: {message}")

    # ---- motion ---------------------------------------------------------------------------
    def start_motion(self, motion: Motion) -> None:
        self.motion, self.motion_done = motion, False

    def direct_torque(self, tau_nm: FloatArray) -> None:
        """`direct_torque(tau)`: joint torques on top of gravity compensation for this cycle
        (from the program's step, before the motion's)."""
        if self.motion is not self.torque or self.motion_done:
            self.target.hold(self.arm.q_rad)
            self.start_motion(self.torque)
        self.torque.set(tau_nm)

    def motion_finished(self, motion: Motion) -> bool:
        return motion is not self.motion or self.motion_done

    def _stop_motion(self, a_rad_s2: float = float("inf")) -> None:
        if self.arm.brakes_released:
            self.start_motion(StopJ(a_rad_s2, self.a_max_rad_s2))

    # ---- safety ---------------------------------------------------------------------------
    def protective_stop(self, reason: str) -> None:
        if self.safety_mode is not SafetyMode.NORMAL or self.robot_mode is not RobotMode.RUNNING:
            return
        log.warning("protective stop: %s", reason)
        self.safety_mode = SafetyMode.PROTECTIVE_STOP
        self.protective_stop_s = self.now_s()
        self.protective_stops += 1
        self.stop_reason = reason
        self.pause_program("protective stop")
        self._stop_motion()

    def unlock_protective_stop(self) -> str:
        """'' once unlocked (or if there was none), else why not yet."""
        if self.safety_mode is not SafetyMode.PROTECTIVE_STOP:
            return ""
        if self.now_s() - self.protective_stop_s < self.unlock_delay_s:
            return (
                f"Cannot unlock protective stop until {self.unlock_delay_s:g}s after occurrence. "
                "Always inspect cause of protective stop before unlocking"
            )
        self.safety_mode = SafetyMode.NORMAL
        self.stop_reason = ""
        log.info("protective stop unlocked")
        return ""

    def emergency_stop(self, mode: SafetyMode = SafetyMode.ROBOT_EMERGENCY_STOP) -> None:
        log.warning("emergency stop (%s)", mode.name)
        self.safety_mode = mode
        self.stop_program("emergency stop")
        if self.arm.brakes_released:
            self.power_off_when_stopped = True
        else:
            self._power_off()

    def release_emergency_stop(self) -> None:
        if self.safety_mode in ESTOPPED:
            self.safety_mode = SafetyMode.NORMAL
            log.info("emergency stop released")

    def restart_safety(self) -> None:
        """Dashboard `restart safety`: the safety system reboots, the arm is powered off."""
        self._power_off()
        self.safety_mode = SafetyMode.NORMAL

    def _check_target(self) -> str:
        """Why the new target violates the limits ('' if it does not)."""
        tgt, arm = self.target, self.arm
        q = tgt.q
        if (q < arm.q_min_rad).any() or (q > arm.q_max_rad).any():
            j = int(np.argmax(np.maximum(arm.q_min_rad - q, q - arm.q_max_rad)))
            lo, hi = arm.q_min_rad[j], arm.q_max_rad[j]
            return f"joint {j} position limit ({q[j]:.4f} rad outside [{lo:g}, {hi:g}])"
        over = np.abs(tgt.qd) - arm.v_max_rad_s * 1.001
        if (over > 0).any():
            j = int(np.argmax(over))
            return f"joint {j} speed limit ({tgt.qd[j]:.3f} rad/s, limit {arm.v_max_rad_s[j]:g})"
        if self.motion.name == "servoj":
            over = np.abs(tgt.qdd) - arm.a_max_rad_s2 * 1.001
            if (over > 0).any():
                j = int(np.argmax(over))
                return (
                    f"joint {j} acceleration limit ({tgt.qdd[j]:.2f} rad/s², limit {arm.a_max_rad_s2[j]:g})"
                )
        return ""

    def _check_tool_force(self) -> None:
        force = float(np.linalg.norm(self.forces.external[0:3]))
        if force > TOOL_FORCE_LIMIT_N and self.safety_mode is SafetyMode.NORMAL:
            self.protective_stop(f"tool force limit ({force:.0f} N, limit {TOOL_FORCE_LIMIT_N:g} N)")

    # ---- watchdog, inputs ---------------------------------------------------------------------
    def set_watchdog(self, register: str, min_frequency_hz: float) -> None:
        self.watchdog = (register, min_frequency_hz) if min_frequency_hz > 0 else None
        self._watch_last_s = self.now_s()

    def inputs_written(self, names: tuple[str, ...]) -> None:
        """An RTDE data package wrote these inputs (feeds the RTDE watchdog). Stamped when it
        arrived, as a controller's receiver does, not with the last cycle's time: a cycle late
        on a loaded machine must not make inputs that kept coming look stale."""
        self.input_packages += 1
        if self.watchdog is not None and self.watchdog[0] in names:
            t0 = self._t0_s
            self._watch_last_s = self.now_s() if t0 is None else self.clock() - t0

    def _check_watchdog(self, now_s: float) -> None:
        if self.watchdog is None or self.runtime_state is not RuntimeState.PLAYING:
            return
        register, hz = self.watchdog
        if now_s - self._watch_last_s > 1.0 / hz:
            log.warning("RTDE watchdog: %s not written for %.3f s", register, now_s - self._watch_last_s)
            self.stop_program(f"RTDE watchdog on {register}")

    # ---- the cycle ------------------------------------------------------------------------
    def step(self, t_s: float) -> None:
        """One controller cycle at wall time `t_s` (CLOCK_MONOTONIC seconds)."""
        c0 = time.perf_counter()
        # cycles this process missed (a loaded machine) must not slow the trajectories down:
        # they advance by the time that passed, up to 10 cycles
        h = self.period_s if self._last_t_s is None else t_s - self._last_t_s
        h = min(max(h, self.period_s), 10.0 * self.period_s)
        self._last_t_s = t_s
        with self.lock:
            if self._t0_s is None:
                self._t0_s = t_s - self.period_s
            now = self._now_s = t_s - self._t0_s
            self.world.now_s = now
            self._advance_power(now)
            arm, tgt = self.arm, self.target
            arm.sample(t_s)
            self.forces.measure()
            self._check_tool_force()
            self.history.append(arm.q_rad.copy())
            playing = self.program is not None and self.runtime_state is RuntimeState.PLAYING
            if playing and self.program is not None and not self.program.step():
                self.stop_program("the program ended")
            self._count_servoj_updates(playing)
            self._check_watchdog(now)
            scaling = self.speed.step(self.state, h)
            if arm.brakes_released:
                self._safe_target.q[:], self._safe_target.qd[:] = tgt.q, tgt.qd
                if self.motion.scaled:
                    self.motion.speed_fraction = scaling
                if not self.motion_done:
                    self.motion_done = self.motion.step(tgt, h)
                torque = self.motion is self.torque and not self.motion_done
                if torque:  # the target is the arm: its limits are checked on the arm itself
                    tgt.q[:], tgt.qd[:] = arm.q_rad, arm.dq_rad_s
                if self.safety_mode is SafetyMode.NORMAL:
                    why = self._check_target()
                    if why:
                        tgt.q[:], tgt.qd[:] = self._safe_target.q, self._safe_target.qd
                        self.protective_stop(why)
                        self.motion_done = self.motion.step(tgt, h)
                        torque = False
                if self.power_off_when_stopped and self.motion_done:
                    self._power_off()
                if torque:
                    arm.apply_torque(t_s, self.torque.tau_nm)
                else:
                    arm.command(t_s, tgt.q)
            else:
                tgt.hold(arm.q_rad)
            self.cycles += 1
            export_state(self, now, (time.perf_counter() - c0) * 1e3)
            for offer in self.subscribers:
                offer(self.cycles)

    # ---- counters for benchmarks (benchmarks/ur_rtde_cycle.py; in `status()`) ---------------
    def _reset_counters(self) -> None:
        self.input_packages = 0  # RTDE input data packages written, by any client
        self._inputs_seen = 0  # `input_packages` at the previous cycle
        self.servoj_cycles = 0  # cycles in which a running servoj took its target
        self.servoj_stale_cycles = 0  # of which no input package had arrived since the last cycle
        self.servoj_overwritten = 0  # packages written over by a newer one before a cycle read them
        self.rtde_packages_skipped = 0  # data packages replaced before a session's thread sent them

    def _count_servoj_updates(self, playing: bool) -> None:
        """After the program's step: did a new servoj target (an input package: ur_rtde writes one
        per servoJ call) reach this cycle? None since the previous cycle: the servo took the
        last target again (a servoJ update missed); more than one: all but the last were lost."""
        fresh = self.input_packages - self._inputs_seen
        self._inputs_seen = self.input_packages
        if not playing or self.motion.name != "servoj" or self.motion_done:
            return
        self.servoj_cycles += 1
        if fresh == 0:
            self.servoj_stale_cycles += 1
        elif fresh > 1:
            self.servoj_overwritten += fresh - 1

    # ---- queries for the control script -----------------------------------------------------
    def set_tcp(self, pose: FloatArray) -> None:
        self.state.tcp_offset[:] = pose
        self.arm.set_tcp_offset(pose)

    def set_payload(self, mass_kg: float, cog_m: FloatArray) -> str:
        """set_payload(mass, cog): the payload the arm carries (its dynamics and the sensor's
        compensation); a zero `cog_m` keeps the present one (ur_rtde's script passes
        get_target_payload_cog() then). '' or why refused (a runtime error)."""
        if not (0.0 <= mass_kg <= RATED_PAYLOAD_KG) or not np.isfinite(cog_m).all():
            rated = RATED_PAYLOAD_KG
            return f"set_payload: mass (={mass_kg:g} kg) must be in [0, {rated:g}] kg (rated payload)"
        self.state.payload_kg = mass_kg
        if cog_m.any():
            self.state.payload_cog[:] = cog_m
        self.arm.set_payload(mass_kg, self.state.payload_cog)
        return ""

    def joint_history(self, steps: int) -> FloatArray:
        if not self.history:
            return self.arm.q_rad.copy()
        k = min(max(steps, 0), len(self.history) - 1)
        return self.history[-1 - k]

    def joint_torques(self) -> FloatArray:
        """`get_joint_torques()`: torque beyond what moving the arm itself takes."""
        return self.arm.tau_nm - self.state.target_moment

    def forward_kin(self, q: FloatArray | None, tcp: FloatArray | None) -> FloatArray:
        out = np.zeros(6)
        if q is None:
            return self.arm.tcp_pose(self.arm.q_rad, out)
        return self.arm.flange_pose(q, tcp if tcp is not None else self.state.tcp_offset, out)

    def within_limits(self, q: FloatArray) -> bool:
        return bool(((q >= self.arm.q_min_rad) & (q <= self.arm.q_max_rad)).all())

    def is_steady(self) -> bool:
        return bool(np.abs(self.arm.dq_rad_s).max() < STEADY_RAD_S) and self.motion_done
