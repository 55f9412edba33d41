"""The velocity guard of torque commands: no torque that would carry a joint past its velocity
limit, whatever the law's gains.

A torque-mode law (computed torque with a large integral gain, a PD without damping) can
command torques within `max_torque_nm` that still accelerate a light joint past
`max_velocity_rad_s` in a few periods; the measured-velocity check then safe-stops the arm
*after* the limit was crossed. The guard acts before the device: from the measured state it
computes the joint accelerations the command would produce (the model's forward dynamics, ABA)
and, where they would take a joint beyond its limit, replaces the command with the torque that
brings it there no faster than over `horizon_periods` periods (inverse dynamics, RNEA):

    ddq_max = (v_max - dq) / (horizon_periods * period),   ddq_min = (-v_max - dq) / (same)

so a joint approaches its limit exponentially and never crosses it in the model; a joint found
beyond it (an estimate's noise, model error) is pulled back. Far from the limits the box is wide
and the command goes through untouched (one ABA, no allocation of note). Tick-safe.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.model import RobotModel
from orccadd.state import FloatArray

HORIZON_PERIODS = 2.0  # a joint closes half its gap to the limit per period, at most


class VelocityGuard:
    """Cuts torque commands that would drive a joint beyond its velocity limit within the
    next periods (see the module docstring)."""

    def __init__(self, model: RobotModel, period_s: float, horizon_periods: float = HORIZON_PERIODS) -> None:
        self.model = model.model
        self.data = model.new_data()
        self.v_max = model.v_max_rad_s.copy()
        self.tau_max = model.tau_max_nm.copy()
        self.horizon_s = horizon_periods * period_s
        # the box's bounds, as lists: the tick tests them with Python floats (see orccadd.vec),
        # the same IEEE operations as the arrays' of the rare path, so the same verdict
        self._v_lo: list[float] = (-self.v_max).tolist()
        self._v_hi: list[float] = self.v_max.tolist()
        self._lo = np.zeros(model.dof)
        self._hi = np.zeros(model.dof)
        self.cut_count = 0  # commands cut since start

    def limit(self, q_rad: FloatArray, dq_rad_s: FloatArray, tau_nm: FloatArray) -> list[float] | None:
        """None if `tau_nm` keeps every joint within its velocity limit (the command goes through
        untouched), else the torques that reach the limit no faster than the horizon allows
        (within ±max_torque_nm)."""
        ddq = pin.aba(self.model, self.data, q_rad, dq_rad_s, tau_nm)
        h = self.horizon_s
        # ddq within [(-v_max - dq) / h, (v_max - dq) / h] for every joint (a NaN is not)
        for a, d, lo_v, hi_v in zip(ddq.tolist(), dq_rad_s.tolist(), self._v_lo, self._v_hi):  # noqa: B905
            if not (lo_v - d) / h <= a <= (hi_v - d) / h:
                return self._cut(q_rad, dq_rad_s, ddq)
        return None

    def _cut(self, q_rad: FloatArray, dq_rad_s: FloatArray, ddq: FloatArray) -> list[float]:
        """The torques that bring `ddq` into the box (the rare path: allocates)."""
        lo, hi = self._lo, self._hi
        np.subtract(-self.v_max, dq_rad_s, out=lo)
        np.subtract(self.v_max, dq_rad_s, out=hi)
        lo /= self.horizon_s
        hi /= self.horizon_s
        self.cut_count += 1
        safe = pin.rnea(self.model, self.data, q_rad, dq_rad_s, np.clip(ddq, lo, hi))
        cut: list[float] = np.clip(safe, -self.tau_max, self.tau_max).tolist()
        return cut
