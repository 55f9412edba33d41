"""Our implementation of ur_rtde's control script (`rtde_control.script`), run when a client
uploads it: the same register protocol, executed one controller cycle at a time.

The protocol (read from the script ur_rtde 1.6 uploads): `input_int_register_0` carries the
command id, the double registers its arguments, int register 1 an `async` flag or an index;
the script writes `output_int_register_0` = 1 (ready for a command) or 2 (done with the
command), `output_int_register_2` the progress of an asynchronous move, and results in the
output double registers. Real-time commands (servoj, speedj, ...) are taken every cycle and
answered "ready"; the others run once per command, and the client clears the command (id 0)
after "done". With the upper range flag every register index is offset by 24.

Commands are the script's ids (ur_rtde `RobotCommand::Type`); ids this simulator does not
model stop the program with a runtime error, so the client's call returns false.

Force side (`force_control.ForceControl`), with the script's register layout:
- 6 force_mode (real-time, re-read every cycle as the script's force thread does): float
  registers 0-5 task frame, 6-11 wrench, 12-17 limits; int register 1 type, 2-7 selection;
- 7 force_mode_stop: end_force_mode() then stopl(10) (here a joint stop at 10 rad/s²);
- 8 zero_ftsensor; 20 force_mode_set_damping, 21 force_mode_set_gain_scaling: float 0 (the
  script sets gain scaling 0.5 and damping 0.025 when it starts);
- 25 tool_contact (real-time): direction in float registers 0-5, the answer in int register 1;
- 52 freedrive_mode: free axes in int registers 1-6, feature in float registers 0-5;
  53 end_freedrive_mode; 54 get_freedrive_status (int register 1); 18/19 teach mode;
- 17 set_payload: mass float 0, centre of gravity floats 1-3 (zero: keep the present one).
A refused argument (out of range, above a safety limit) is a runtime error: the program stops,
and the client's next call returns false.
"""

from __future__ import annotations

import logging
import re
from typing import Protocol

import numpy as np

from orccadd.state import FloatArray
from orccadd.ursim.force_control import ForceControl
from orccadd.ursim.force_mode import Admittance, ForceModeArgs
from orccadd.ursim.motion import Motion, MoveJ, ServoJ, SpeedJ, StopJ
from orccadd.ursim.robot_state import RobotState
from orccadd.ursim.series import Series

log = logging.getLogger("orccadd.ursim")

RDY_FOR_CMD = 1  # UR_CONTROLLER_RDY_FOR_CMD
DONE_WITH_CMD = 2  # UR_CONTROLLER_DONE_WITH_CMD
STOP_SCRIPT = 255
REALTIME = frozenset({6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})
COMMAND_NAMES = {
    1: "movej", 2: "movej_ik", 3: "movel", 4: "movel_fk", 6: "force_mode", 7: "force_mode_stop",
    8: "zero_ftsensor", 9: "speedj", 10: "speedl", 11: "servoj", 12: "servoc", 15: "speed_stop",
    16: "servo_stop", 17: "set_payload", 18: "teach_mode", 19: "end_teach_mode",
    20: "force_mode_set_damping", 21: "force_mode_set_gain_scaling", 24: "servol", 25: "tool_contact",
    26: "get_steptime", 27: "get_actual_joint_positions_history", 28: "get_target_waypoint",
    29: "set_tcp", 30: "get_inverse_kin", 31: "protective_stop", 33: "stopl", 34: "stopj",
    35: "set_watchdog", 36: "is_pose_within_safety_limits", 37: "is_joints_within_safety_limits",
    38: "get_joint_torques", 39: "pose_trans", 40: "get_tcp_offset", 41: "jog_start", 42: "jog_stop",
    43: "get_forward_kin", 44: "get_forward_kin_args", 45: "move_path", 46: "get_inverse_kin_default",
    47: "is_steady", 51: "move_until_contact", 52: "freedrive_mode", 53: "end_freedrive_mode",
    54: "get_freedrive_status", 55: "set_external_force_torque", 56: "ft_rtde_input_enable",
    57: "enable_external_ft_sensor", 58: "get_actual_tool_flange_pose", 59: "set_gravity",
}  # fmt: skip
MARKER = "RTDE Control Script"  # the textmsg of ur_rtde's script: how it is recognised
SCRIPT_GAIN_SCALING, SCRIPT_DAMPING = 0.5, 0.025  # set by the script when it starts
FORCE_MODE_STOP_RAD_S2 = 10.0  # the script's stopl(10) after end_force_mode()


class Program(Protocol):
    """A running program: one step per controller cycle while it plays."""

    name: str

    def step(self) -> bool:
        """Run one cycle's worth; False once the program has ended."""
        ...


class ScriptHost(Protocol):
    """What the control script needs from the controller (`controller.UrController`)."""

    state: RobotState
    series: Series
    period_s: float
    v_max_rad_s: FloatArray
    a_max_rad_s2: FloatArray
    forces: ForceControl

    def start_motion(self, motion: Motion) -> None: ...
    def motion_finished(self, motion: Motion) -> bool: ...
    def protective_stop(self, reason: str) -> None: ...
    def set_watchdog(self, register: str, min_frequency_hz: float) -> None: ...
    def set_tcp(self, pose: FloatArray) -> None: ...
    def set_payload(self, mass_kg: float, cog_m: FloatArray) -> str: ...
    def joint_history(self, steps: int) -> FloatArray: ...
    def joint_torques(self) -> FloatArray: ...
    def direct_torque(self, tau_nm: FloatArray) -> None: ...
    def forward_kin(self, q: FloatArray | None, tcp: FloatArray | None) -> FloatArray: ...
    def within_limits(self, q: FloatArray) -> bool: ...
    def is_steady(self) -> bool: ...
    def runtime_error(self, message: str) -> None: ...


def is_control_script(text: str) -> bool:
    return MARKER in text


def register_offsets(text: str) -> tuple[int, int]:
    """The (int, float) register offsets ur_rtde injected (0, or 24 for the upper range).

    ur_rtde inserts the number after the line `global reg_offset_int = # int register offset`,
    at the start of the next line: the value follows the `=` past a comment and a newline."""
    found = []
    for kind in ("reg_offset_int", "reg_offset_float"):
        m = re.search(rf"global\s+{kind}\s*=\s*(?:#[^\n]*\n\s*)?(\d+)", text)
        found.append(int(m[1]) if m else 0)
    return found[0], found[1]


class ControlScript:
    """ur_rtde's control program, one pass of its main loop per controller cycle."""

    name = "rtde_control"

    def __init__(self, host: ScriptHost, int_offset: int = 0, float_offset: int = 0) -> None:
        self.host = host
        self.s = host.state
        self.oi, self.of = int_offset, float_offset
        n = len(host.v_max_rad_s)
        self.servo = ServoJ(n)
        self.speed = SpeedJ(host.a_max_rad_s2)
        self.is_servoing = self.is_speeding = False
        self.speed_type = 1
        self.executing_cmd = False
        self.blocking: Motion | None = None  # the main thread is inside movej/stopj/...
        self.async_motion: Motion | None = None  # a move or stop thread
        self.async_wr_count = 0
        self.async_op_id = 0
        self.started = False
        self.compliant: Admittance | None = None  # force mode or freedrive running

    # ---- registers ------------------------------------------------------------------------
    def _int(self, i: int) -> int:
        return self.s.in_int[i + self.oi]

    def _float(self, i: int) -> float:
        return self.s.in_double[i + self.of]

    def _q(self, i: int) -> FloatArray:
        return np.array([self._float(i + k) for k in range(6)])

    def _out_int(self, i: int, v: int) -> None:
        self.s.out_int[i + self.oi] = v

    def _out_floats(self, i: int, values: FloatArray) -> None:
        for k, v in enumerate(values):
            self.s.out_double[i + k + self.of] = float(v)

    def _async_progress(self, value: int) -> None:
        """`output_int_register_2`: op id (bits 24-30), write count (16-23), running (15),
        progress (0-14), as the script's `write_async_progress_register`."""
        self.async_wr_count = (self.async_wr_count + 1) % 128
        if value == 0:
            self.async_op_id = (self.async_op_id + 1) % 128
        reg = self.async_wr_count * 65536 + self.async_op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._out_int(2, reg)

    # ---- main loop ------------------------------------------------------------------------
    def step(self) -> bool:
        """One pass of the script's main loop; False once the script has ended."""
        if not self.started:
            self.started = True
            log.info("%s: RTDE Control Script Loaded", self.name)
            self.host.forces.set_gain_scaling(SCRIPT_GAIN_SCALING)
            self.host.forces.set_damping(SCRIPT_DAMPING)
            self._async_progress(-1)
            self._out_int(0, RDY_FOR_CMD)
        if self.async_motion is not None and self.host.motion_finished(self.async_motion):
            self.async_motion = None
            self._async_progress(-1)
        if self.blocking is not None:
            if not self.host.motion_finished(self.blocking):
                return True
            self.blocking = None
            self._out_int(0, DONE_WITH_CMD)
            return True
        cmd = self._int(0)
        if cmd in REALTIME:
            keep = self._process(cmd)
            self._out_int(0, RDY_FOR_CMD)
            return keep
        if cmd == 0:
            self.executing_cmd = False
            self._out_int(0, RDY_FOR_CMD)
            return True
        keep = True
        if not self.executing_cmd:
            keep = self._process(cmd)
            if keep and self.blocking is None:
                self._out_int(0, DONE_WITH_CMD)
        self.executing_cmd = True
        return keep

    def _stop_threads(self) -> None:
        self.is_servoing = self.is_speeding = False
        if self.async_motion is not None:
            self.async_motion = None
            self._async_progress(-1)

    def _stop(self, a: float, motion_async: bool) -> None:
        self._stop_threads()
        stop = StopJ(a, self.host.a_max_rad_s2)
        self.host.start_motion(stop)
        if motion_async:
            self.async_motion = stop
            self._async_progress(0)
        else:
            self.blocking = stop

    def _process(self, cmd: int) -> bool:
        """Execute one command (its effect on registers and motion); False: the script ends."""
        if cmd in FORCE_COMMANDS:
            why = self._force_command(cmd)
            if why:
                self.host.runtime_error(why)
                return False
            return True
        h = self.host
        if cmd == 1:  # movej
            move = MoveJ(self._q(0), self._float(6), self._float(7), h.v_max_rad_s, h.a_max_rad_s2)
            self._stop_threads()
            h.start_motion(move)
            if self._int(1) == 1:
                self.async_motion = move
                self._async_progress(0)
            else:
                self.blocking = move
        elif cmd == 9:  # speedj
            self.speed.set(self._q(0), self._float(6))
            self.speed_type = 1
            if not self.is_speeding or h.motion_finished(self.speed):  # not, or stopped since
                self._stop_threads()
                self.is_speeding = True
                h.start_motion(self.speed)
        elif cmd == 11:  # servoj
            self.servo.set(self._q(0), self._float(9), self._float(10))
            if not self.is_servoing or h.motion_finished(self.servo):
                self._stop_threads()
                self.is_servoing = True
                h.start_motion(self.servo)
        elif cmd == 66:  # direct_torque: the script's lines for it exist on 5.26 and later only
            if h.series.direct_torque:
                self._stop_threads()
                h.direct_torque(self._q(0))
        elif cmd in (15, 16):  # speed_stop, servo_stop
            self._stop(self._float(0), motion_async=False)
        elif cmd in (33, 34):  # stopl (in joint space here), stopj
            self._stop(self._float(0), motion_async=self._int(1) == 1)
        elif cmd == 31:
            h.protective_stop("protective_stop() from the program")
        elif cmd == 35:
            h.set_watchdog(f"input_int_register_{self.oi}", self._float(0))
        elif cmd == 17:
            why = h.set_payload(self._float(0), np.array([self._float(1), self._float(2), self._float(3)]))
            if why:
                h.runtime_error(why)
                return False
        elif cmd == 26:
            self._out_floats(0, np.array([h.period_s]))
        elif cmd == 27:
            self._out_floats(0, h.joint_history(self._int(1)))
        elif cmd == 29:
            h.set_tcp(self._q(0))
        elif cmd == 37:
            self._out_int(1, int(h.within_limits(self._q(0))))
        elif cmd == 38:
            self._out_floats(0, h.joint_torques())
        elif cmd == 40:
            self._out_floats(0, self.s.tcp_offset)
        elif cmd == 43:
            self._out_floats(0, h.forward_kin(None, None))
        elif cmd == 44:
            self._out_floats(0, h.forward_kin(self._q(0), self._q(6)))
        elif cmd == 47:
            self._out_int(1, int(h.is_steady()))
        elif cmd == STOP_SCRIPT:
            log.info("%s: received stop script", self.name)
            return False
        else:
            name = COMMAND_NAMES.get(cmd, "unknown")
            h.runtime_error(f"command {cmd} ({name}) is not simulated")
            return False
        return True

    # ---- force mode, freedrive, the sensor ---------------------------------------------------
    def _running(self, name: tuple[str, ...]) -> Admittance | None:
        c = self.compliant
        return c if c is not None and c.name in name and not self.host.motion_finished(c) else None

    def _start_compliant(self, made: Admittance | str) -> str:
        if isinstance(made, str):
            return made
        self._stop_threads()
        self.compliant = made
        self.host.start_motion(made)
        return ""

    def _force_command(self, cmd: int) -> str:
        """A force-side command: '' or the runtime error that stops the program."""
        f = self.host.forces
        if cmd == 6:
            args = ForceModeArgs(
                tuple(self._q(0)),
                tuple(self._int(2 + k) for k in range(6)),
                tuple(self._q(6)),
                self._int(1),
                tuple(self._q(12)),
            )
            made = f.force_mode(args)
            running = self._running(("force_mode",))
            if running is not None and not isinstance(made, str):
                running.update(args)
                return ""
            return self._start_compliant(made)
        if cmd == 7:
            self.compliant = None
            self._stop(FORCE_MODE_STOP_RAD_S2, motion_async=False)
        elif cmd == 8:
            f.zero_ftsensor()
        elif cmd == 20:
            return f.set_damping(self._float(0))
        elif cmd == 21:
            return f.set_gain_scaling(self._float(0))
        elif cmd == 25:
            self._out_int(1, f.tool_contact(self._q(0)))
        elif cmd == 52:
            axes = tuple(self._int(1 + k) for k in range(6))
            return self._start_compliant(f.freedrive(axes, tuple(self._q(0)), "freedrive"))
        elif cmd == 18:
            return self._start_compliant(f.freedrive((1,) * 6, (0.0,) * 6, "teach_mode"))
        elif cmd in (19, 53):
            if self._running(("freedrive", "teach_mode")) is not None:
                self.compliant = None
                self._stop(float("inf"), motion_async=False)
        elif cmd == 54:
            self._out_int(1, f.freedrive_status())
        return ""


FORCE_COMMANDS = frozenset({6, 7, 8, 18, 19, 20, 21, 25, 52, 53, 54})
