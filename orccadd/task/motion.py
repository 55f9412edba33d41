"""The motion of a position command, from the last commands a task sent: what a task switched to
continues (`RobotTask.continue_from`), so a position-controlled arm's reference stays continuous
in position and velocity across the switch, not only in position.

Time is the command stream's own: one command per `period_s` (a servo, servoJ or CSP, takes one
per cycle), never the ticks' clock readings, which jitter (a late tick and the next one close
behind it would make a speed of the same step ten times too high).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from orccadd.modules.base import CommandMotion


class CommandHistory:
    """The last three commands sent, one per `period_s` (a ring, preallocated; tick-safe)."""

    def __init__(self, dof: int, period_s: float) -> None:
        self.period_s = period_s
        self._q = np.zeros((3, dof))
        self._i = 0  # the slot of the last command
        self._n = 0  # commands recorded since `clear` (up to 3)
        self._scratch = np.zeros(dof)

    def clear(self) -> None:
        self._n = 0

    def record(self, command: npt.NDArray[np.float64]) -> None:
        i = self._i = (self._i + 1) % 3
        self._q[i] = command
        if self._n < 3:
            self._n += 1

    def motion(self, out: CommandMotion) -> bool:
        """Fill `out` with the last command and its velocity and acceleration when it was sent
        (finite differences over `period_s`, the velocity carried from the last interval's
        middle to its end; zero where fewer commands were sent). False if none was."""
        n = self._n
        if not n:
            return False
        i, q, dt = self._i, self._q, self.period_s
        out.q_rad[:] = q[i]
        out.dq_rad_s[:] = 0.0
        out.ddq_rad_s2[:] = 0.0
        if n >= 2:
            np.subtract(q[i], q[i - 1], out=out.dq_rad_s)
            out.dq_rad_s /= dt
        if n == 3:
            np.subtract(q[i], q[i - 1], out=out.ddq_rad_s2)
            out.ddq_rad_s2 -= q[i - 1]
            out.ddq_rad_s2 += q[i - 2]
            out.ddq_rad_s2 /= dt * dt
            np.multiply(out.ddq_rad_s2, 0.5 * dt, out=self._scratch)
            out.dq_rad_s += self._scratch
        return True


def extrapolate(motion: CommandMotion, dt_s: float, out: npt.NDArray[np.float64]) -> None:
    """Where `motion` goes on to `dt_s` later (q + v·dt + a·dt²/2): the command a task switched
    to should send first, to continue the outgoing one's without a step in velocity."""
    np.multiply(motion.ddq_rad_s2, 0.5 * dt_s, out=out)
    out += motion.dq_rad_s
    out *= dt_s
    out += motion.q_rad
