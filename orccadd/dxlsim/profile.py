"""A servo's profile generator: Goal Position (or Goal Velocity) becomes a trajectory.

e-Manual, Profile Velocity(112) / Profile Acceleration(108) and Drive Mode(10) bit 2: in the
velocity-based profile both are a velocity (0.229 rpm) and an acceleration (214.577 rev/min²),
0 meaning unlimited; in the time-based profile they are the whole move's time and its
acceleration time in ms. The moving status reports the profile's shape: rectangular (no
acceleration limit), triangular (the top velocity is never reached) or trapezoidal.

The generator runs online (one step per control period), so a new goal mid-move blends from the
present trajectory state instead of restarting.
"""

from __future__ import annotations

import math

INF = math.inf
TICKS_PER_REV = 4096
VELOCITY_UNIT_RPM = 0.229
ACCELERATION_UNIT_RPM2 = 214.577
TICKS_S_PER_VELOCITY_UNIT = VELOCITY_UNIT_RPM / 60.0 * TICKS_PER_REV  # 15.63 ticks/s
TICKS_S2_PER_ACCELERATION_UNIT = ACCELERATION_UNIT_RPM2 / 3600.0 * TICKS_PER_REV  # 244.1 ticks/s²

NO_PROFILE, RECTANGULAR, TRIANGULAR, TRAPEZOIDAL = 0x00, 0x10, 0x20, 0x30


class PositionProfile:
    """Position trajectory (ticks, ticks/s) towards a goal, velocity and acceleration limited."""

    def __init__(self) -> None:
        self.position = 0.0
        self.velocity = 0.0
        self.acceleration = 0.0
        self.goal = 0.0
        self.v_max = INF
        self.a_max = INF
        self.shape = NO_PROFILE

    @property
    def ongoing(self) -> bool:
        return self.position != self.goal or self.velocity != 0.0

    def reset(self, position: float) -> None:
        """Stand still at `position` (torque switched on, reboot, bus watchdog stop)."""
        self.position = self.goal = position
        self.velocity = self.acceleration = 0.0

    def set_goal(
        self, goal: float, profile_velocity: int, profile_acceleration: int, time_based: bool
    ) -> None:
        """A new Goal Position with the profile items as written in the table."""
        self.goal = goal
        distance = abs(goal - self.position)
        if time_based:
            total_s, acc_s = (
                profile_velocity / 1000.0,
                min(profile_acceleration, profile_velocity // 2) / 1000.0,
            )
            if total_s <= 0.0 or distance == 0.0:
                self.v_max, self.a_max = INF, INF
            else:
                self.v_max = distance / (total_s - acc_s)
                self.a_max = self.v_max / acc_s if acc_s > 0.0 else INF
        else:
            self.v_max = profile_velocity * TICKS_S_PER_VELOCITY_UNIT if profile_velocity else INF
            self.a_max = (
                profile_acceleration * TICKS_S2_PER_ACCELERATION_UNIT if profile_acceleration else INF
            )
        if math.isinf(self.v_max):
            self.shape = NO_PROFILE
        elif math.isinf(self.a_max):
            self.shape = RECTANGULAR
        else:
            self.shape = TRAPEZOIDAL if self.v_max**2 / self.a_max < distance else TRIANGULAR

    def step(self, h_s: float) -> None:
        """Advance the trajectory by `h_s` seconds."""
        v0 = self.velocity
        d = self.goal - self.position
        if math.isinf(self.v_max) or (abs(d) < 1e-6 and abs(v0) < 1e-6):
            self.position, self.velocity = self.goal, 0.0
        else:
            reach = math.sqrt(2.0 * self.a_max * abs(d)) if not math.isinf(self.a_max) else abs(d) / h_s
            v_des = math.copysign(min(self.v_max, reach, abs(d) / h_s), d)
            dv = v_des - v0
            if not math.isinf(self.a_max):
                dv = max(-self.a_max * h_s, min(self.a_max * h_s, dv))
            self.velocity = v0 + dv
            self.position += self.velocity * h_s
            if (self.goal - self.position) * d <= 0.0:  # arrived (or passed): stop on the goal
                self.position, self.velocity = self.goal, 0.0
        self.acceleration = (self.velocity - v0) / h_s


class VelocityProfile:
    """Velocity trajectory (ticks/s) towards Goal Velocity, acceleration limited."""

    def __init__(self) -> None:
        self.velocity = 0.0
        self.goal = 0.0
        self.a_max = INF

    def set_goal(self, goal: float, profile_acceleration: int) -> None:
        self.goal = goal
        self.a_max = profile_acceleration * TICKS_S2_PER_ACCELERATION_UNIT if profile_acceleration else INF

    def step(self, h_s: float) -> None:
        dv = self.goal - self.velocity
        if not math.isinf(self.a_max):
            dv = max(-self.a_max * h_s, min(self.a_max * h_s, dv))
        self.velocity += dv
