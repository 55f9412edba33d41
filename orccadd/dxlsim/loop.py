"""A servo's own control loops and motor, one control period at a time.

The e-Manual's block diagrams (Position PID Gain, Velocity PI Gain, Current-based Position):

- position / extended position (3, 4): profile -> PID + feed-forward -> PWM;
- current-based position (5): profile -> PID + feed-forward -> current, limited by Goal
  Current -> current loop -> PWM;
- velocity (1): profile -> PI -> PWM;  current (0): Goal Current -> current loop -> PWM;
  PWM (16): Goal PWM. In every mode Goal PWM limits the PWM.

Gains as the e-Manual converts them: KPP = P/128, KPI = I/65536, KPD = D/16, KVP = P/128,
KVI = I/65536. The units of the signals they multiply are not published; here: position error
in pulses, its integral in pulse·ms, its derivative in pulses/ms, velocity error in 0.229 rpm
units, its integral in unit·ms, outputs in PWM units (885 = 100 %) or current units. The
feed-forward gains (table value / 4) are scaled so that 100 (table 400) is the exact no-load
velocity (1st) or rotor-inertia (2nd) feed-forward of the model. The current loop is ideal.

The motor is a DC motor on its torque-speed line at the model's rated voltage:
τ = τ_stall · (duty − ω/ω_no_load), current likewise with I_stall; torque off leaves the bridge
open (no torque, no braking). Overload (our rule): the output saturated at under a tenth of the
no-load speed for `OVERLOAD_TIME_S`. Temperature: first order towards ambient plus
`STALL_RISE_K` × (I/I_stall)², time constant `THERMAL_TAU_S`.
"""

from __future__ import annotations

import math

from orccadd.dxlsim import table as T
from orccadd.dxlsim.models import ServoModel
from orccadd.dxlsim.profile import TICKS_PER_REV, TICKS_S_PER_VELOCITY_UNIT, PositionProfile, VelocityProfile

TICKS_PER_RAD = TICKS_PER_REV / (2.0 * math.pi)
CENTER = 2048  # the pulse at horn angle 0
PWM_FULL = 885.0
OVERLOAD_TIME_S = 1.0
AMBIENT_C = 30.0
STALL_RISE_K = 60.0
THERMAL_TAU_S = 120.0
IN_POSITION_TICKS = 10
POSITION_MODES = (3, 4, 5)


class ServoLoop:
    """Control state of one servo; reads its gains, goals and limits from the table."""

    def __init__(self, model: ServoModel, table: T.ControlTable) -> None:
        self.model = model
        self.t = table
        self.profile = PositionProfile()
        self.vprofile = VelocityProfile()
        self.turns = 0
        self.theta_rad = 0.0  # horn angle, servo's own sense (before Drive Mode)
        self.omega_rad_s = 0.0
        self.duty = 0.0  # user sense (after Drive Mode), -1..1
        self.current_a = 0.0  # user sense
        self.temperature_c = AMBIENT_C
        self.overloaded = False
        self._i_pos = 0.0
        self._i_vel = 0.0
        self._overload_s = 0.0

    # ---- frames ---------------------------------------------------------------------------
    @property
    def sense(self) -> float:
        return -1.0 if self.t.get(T.DRIVE_MODE) & 0x01 else 1.0

    def position_ticks(self) -> float:
        """Present Position as a real number: pulses, homing offset and turns included."""
        raw = self.sense * self.theta_rad * TICKS_PER_RAD + CENTER + TICKS_PER_REV * self.turns
        return raw + self.t.get(T.HOMING_OFFSET)

    def velocity_ticks_s(self) -> float:
        return self.sense * self.omega_rad_s * TICKS_PER_RAD

    def clear_turns(self) -> None:
        """Present Position back into one turn, [0, 4096) (Clear instruction, torque on in mode 3)."""
        self.turns -= math.floor((self.position_ticks() - self.t.get(T.HOMING_OFFSET)) / TICKS_PER_REV)

    @property
    def moving(self) -> bool:
        speed_units = abs(self.velocity_ticks_s()) / TICKS_S_PER_VELOCITY_UNIT
        return speed_units > self.t.get(T.MOVING_THRESHOLD) or self.profile.ongoing

    # ---- events from the table ------------------------------------------------------------
    def boot(self) -> None:
        self.clear_turns()
        self.t.set(T.GOAL_POSITION, round(self.position_ticks()))
        self.torque_off()
        self._overload_s = 0.0
        self.overloaded = False

    def torque_on(self) -> None:
        if self.t.get(T.OPERATING_MODE) == 3:
            self.clear_turns()
        self._i_pos = self._i_vel = 0.0
        self.profile.reset(self.position_ticks())
        self.goal_position_written()
        self.vprofile.velocity = self.velocity_ticks_s()
        self.goal_velocity_written()

    def torque_off(self) -> None:
        self.duty = self.current_a = 0.0
        self._i_pos = self._i_vel = 0.0
        self._overload_s = 0.0

    def goal_position_written(self) -> None:
        self.profile.set_goal(
            float(self.t.get(T.GOAL_POSITION)),
            self.t.get(T.PROFILE_VELOCITY),
            self.t.get(T.PROFILE_ACCELERATION),
            time_based=bool(self.t.get(T.DRIVE_MODE) & 0x04),
        )

    def goal_velocity_written(self) -> None:
        goal = self.t.get(T.GOAL_VELOCITY) * TICKS_S_PER_VELOCITY_UNIT
        self.vprofile.set_goal(goal, self.t.get(T.PROFILE_ACCELERATION))

    def stop_here(self, theta_rad: float) -> None:
        """Bus watchdog: stop at once (profiles applied as 0) and stay."""
        self.theta_rad = theta_rad
        self.profile.reset(self.position_ticks())
        self.vprofile.velocity = self.vprofile.goal = 0.0

    def watchdog_cleared(self) -> None:
        self.goal_velocity_written()

    # ---- one control period ---------------------------------------------------------------
    def step(self, theta_rad: float, omega_rad_s: float, h_s: float) -> float:
        """Torque on the horn (N·m, servo's own sense) for the next `h_s` seconds."""
        self.theta_rad, self.omega_rad_s = theta_rad, omega_rad_s
        m = self.model
        s = self.sense
        w_user = s * omega_rad_s / m.no_load_speed_rad_s  # speed as a fraction of no-load
        saturated = False
        if not self.t.get(T.TORQUE_ENABLE):
            self.profile.reset(self.position_ticks())
            self.duty = 0.0
        else:
            pwm_cap = min(abs(self.t.get(T.GOAL_PWM)), self.t.get(T.PWM_LIMIT)) / PWM_FULL
            mode = self.t.get(T.OPERATING_MODE)
            if mode == 16:
                duty = self.t.get(T.GOAL_PWM) / PWM_FULL
            elif mode == 0:
                duty = self._current_loop(self._current_goal() * m.current_unit_a, w_user)
            elif mode == 1:
                duty = self._velocity_pi(h_s)
            else:
                self.profile.step(h_s)
                u = self._position_pid(h_s)
                if mode == 5:
                    # held at the current cap is a grip, not an overload: only a motor at its
                    # full output (the PWM's saturation, below) overloads
                    cap = abs(self._current_goal())
                    duty = self._current_loop(max(-cap, min(cap, u)) * m.current_unit_a, w_user)
                else:
                    duty = u / PWM_FULL
            saturated = saturated or abs(duty) >= pwm_cap
            self.duty = max(-pwm_cap, min(pwm_cap, duty))
        if self.t.get(T.TORQUE_ENABLE):
            self.current_a = m.stall_current_a * (self.duty - w_user)
        else:
            self.current_a = 0.0
        self._watch_load(saturated and abs(w_user) < 0.1, h_s)
        return s * self.current_a * m.torque_constant_nm_a

    def _current_goal(self) -> int:
        """Goal Current(102) within Current Limit(38): lowering the limit lowers the torque in
        torque and current-based position modes (e-Manual, Current Limit), whatever Goal Current
        was written before."""
        goal, limit = self.t.get(T.GOAL_CURRENT), self.t.get(T.CURRENT_LIMIT)
        return max(-limit, min(limit, goal))

    def _current_loop(self, current_a: float, w_user: float) -> float:
        return current_a / self.model.stall_current_a + w_user

    def _position_pid(self, h_s: float) -> float:
        t, p = self.t, self.profile
        ms = h_s * 1000.0
        error = p.position - self.position_ticks()
        kpp, kpi, kpd = (
            t.get(T.POSITION_P_GAIN) / 128,
            t.get(T.POSITION_I_GAIN) / 65536,
            t.get(T.POSITION_D_GAIN) / 16,
        )
        self._i_pos += error * ms
        if kpi:
            bound = PWM_FULL / kpi
            self._i_pos = max(-bound, min(bound, self._i_pos))
        d_error = (p.velocity - self.velocity_ticks_s()) / 1000.0
        ff1 = t.get(T.FEEDFORWARD_1ST_GAIN) / 400.0
        ff2 = t.get(T.FEEDFORWARD_2ND_GAIN) / 400.0
        m = self.model
        v_nl_ticks_s = m.no_load_speed_rad_s * TICKS_PER_RAD
        inertia_duty = m.rotor_inertia_kg_m2 * p.acceleration / TICKS_PER_RAD / m.stall_torque_nm
        ff = PWM_FULL * (ff1 * p.velocity / v_nl_ticks_s + ff2 * inertia_duty)
        return kpp * error + kpi * self._i_pos + kpd * d_error + ff

    def _velocity_pi(self, h_s: float) -> float:
        t = self.t
        self.vprofile.step(h_s)
        error = (self.vprofile.velocity - self.velocity_ticks_s()) / TICKS_S_PER_VELOCITY_UNIT
        kvp, kvi = t.get(T.VELOCITY_P_GAIN) / 128, t.get(T.VELOCITY_I_GAIN) / 65536
        self._i_vel += error * h_s * 1000.0
        if kvi:
            bound = PWM_FULL / kvi
            self._i_vel = max(-bound, min(bound, self._i_vel))
        return (kvp * error + kvi * self._i_vel) / PWM_FULL

    def _watch_load(self, stalled_at_limit: bool, h_s: float) -> None:
        self._overload_s = self._overload_s + h_s if stalled_at_limit else 0.0
        self.overloaded = self._overload_s > OVERLOAD_TIME_S
        heat = STALL_RISE_K * (self.current_a / self.model.stall_current_a) ** 2
        self.temperature_c += (AMBIENT_C + heat - self.temperature_c) * min(1.0, h_s / THERMAL_TAU_S)

    # ---- the table's measurements ---------------------------------------------------------
    def refresh(self, now_s: float) -> None:
        """Write the present values into the table (before a read)."""
        t, p = self.t, self.profile
        cu = self.model.current_unit_a
        t.set(T.PRESENT_POSITION, round(self.position_ticks()))
        t.set(T.PRESENT_VELOCITY, round(self.velocity_ticks_s() / TICKS_S_PER_VELOCITY_UNIT))
        t.set(T.PRESENT_PWM, round(self.duty * PWM_FULL))
        t.set(T.PRESENT_CURRENT, round(self.current_a / cu))
        t.set(T.PRESENT_TEMPERATURE, round(self.temperature_c))
        t.set(T.REALTIME_TICK, int(now_s * 1000.0) % 32768)
        mode = t.get(T.OPERATING_MODE)
        if mode in POSITION_MODES:
            t.set(T.POSITION_TRAJECTORY, round(p.position))
            t.set(T.VELOCITY_TRAJECTORY, round(p.velocity / TICKS_S_PER_VELOCITY_UNIT))
        elif mode == 1:
            t.set(T.VELOCITY_TRAJECTORY, round(self.vprofile.velocity / TICKS_S_PER_VELOCITY_UNIT))
        t.set(T.MOVING, int(self.moving))
        status = 0
        if t.get(T.TORQUE_ENABLE) and mode in POSITION_MODES:
            status = p.shape
            if p.ongoing:
                status |= 0x02
            elif abs(t.get(T.GOAL_POSITION) - self.position_ticks()) <= IN_POSITION_TICKS:
                status |= 0x01
        t.set(T.MOVING_STATUS, status)
