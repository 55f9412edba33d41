"""Commands in joint units → the goal values the servos take, and the laws that hold the arm
or follow the safe stop's ramp in each command mode (tick-safe: lists and one Pinocchio call).

- position: Goal Position in ticks, within Min/Max Position Limit in position mode (3) (the
  servo would refuse a goal beyond them, silently in a Sync Write);
- velocity: Goal Velocity in 0.229 rpm units within Velocity Limit; following a reference
  (q_ref, v_ref): v = v_ref + `KP_VELOCITY_1_S` · (q_ref − q);
- current: Goal Current in the model's unit within Current Limit; following a reference: the
  inverse dynamics (RNEA) of a ← a_ref + ω²(q_ref − q) + 2ω(v_ref − dq), ω = `HOLD_OMEGA_RAD_S`,
  so the servos' current loops hold the arm against gravity as a stiff, damped spring.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel.models import POSITION
from orccadd.drivers.dynamixel.startup import EepromTarget
from orccadd.drivers.dynamixel.units import CENTER_TICKS, JointUnits
from orccadd.model import RobotModel
from orccadd.types import CommandMode

KP_VELOCITY_1_S = 10.0
HOLD_OMEGA_RAD_S = 20.0
GOAL_POSITION_MAX = 1_048_575


def _clamp(v: int, lo: int, hi: int) -> int:
    return lo if v < lo else hi if v > hi else v


class Goals:
    """Unit conversions and limits of the goals, per joint."""

    def __init__(
        self, units: Sequence[JointUnits], targets: Sequence[EepromTarget], model: RobotModel
    ) -> None:
        self.offset = [u.offset_rad for u in units]
        self.rad_per_tick = [u.rad_per_tick for u in units]
        self.rad_s_per_unit = [u.rad_s_per_unit for u in units]
        self.nm_per_unit = [u.nm_per_unit for u in units]
        self.velocity_max = [t.values[T.VELOCITY_LIMIT] for t in targets]
        self.current_max = [t.values.get(T.CURRENT_LIMIT, 0) for t in targets]
        self._pos_lo = [t.values[T.MIN_POSITION_LIMIT] for t in targets]
        self._pos_hi = [t.values[T.MAX_POSITION_LIMIT] for t in targets]
        self.tick_lo = [-GOAL_POSITION_MAX] * len(units)
        self.tick_hi = [GOAL_POSITION_MAX] * len(units)
        self.model = model
        self._data = model.new_data()
        self._tau_max = model.tau_max_nm.tolist()

    def set_operating_modes(self, modes: Sequence[int]) -> None:
        """Position mode (3) keeps goals within the position limits; the others need not."""
        for j, m in enumerate(modes):
            pos = m == POSITION
            self.tick_lo[j] = self._pos_lo[j] if pos else -GOAL_POSITION_MAX
            self.tick_hi[j] = self._pos_hi[j] if pos else GOAL_POSITION_MAX

    # ---- joint units -> goals ---------------------------------------------------------------
    def positions(self, q_rad: Sequence[float]) -> list[int]:
        return [
            _clamp(round(CENTER_TICKS + (q - o) / k), lo, hi)
            for q, o, k, lo, hi in zip(
                q_rad, self.offset, self.rad_per_tick, self.tick_lo, self.tick_hi, strict=True
            )
        ]

    def velocities(self, dq_rad_s: Sequence[float]) -> list[int]:
        return [
            _clamp(round(v / k), -m, m)
            for v, k, m in zip(dq_rad_s, self.rad_s_per_unit, self.velocity_max, strict=True)
        ]

    def currents(self, tau_nm: Sequence[float]) -> list[int]:
        return [
            _clamp(round(t / k), -m, m)
            for t, k, m in zip(tau_nm, self.nm_per_unit, self.current_max, strict=True)
        ]

    def command(self, mode: CommandMode, values: Sequence[float]) -> list[int]:
        if mode is CommandMode.POSITION:
            return self.positions(values)
        if mode is CommandMode.VELOCITY:
            return self.velocities(values)
        return self.currents(values)

    # ---- servo units -> joint units -----------------------------------------------------------
    def joint_positions(self, ticks: Sequence[int]) -> list[float]:
        return [
            o + (p - CENTER_TICKS) * k for o, p, k in zip(self.offset, ticks, self.rad_per_tick, strict=True)
        ]

    # ---- holding and following a reference ------------------------------------------------------
    def gravity(self, q_rad: Sequence[float]) -> list[int]:
        """Goal Currents that hold the arm at `q_rad` against gravity."""
        tau = pin.computeGeneralizedGravity(self.model.model, self._data, np.asarray(q_rad, dtype=np.float64))
        return self.currents(tau.tolist())

    def follow(
        self,
        mode: CommandMode,
        q_ref: Sequence[float],
        v_ref: Sequence[float],
        a_ref: Sequence[float],
        q: Sequence[float],
        dq: Sequence[float],
    ) -> list[int]:
        """Goals that follow (q_ref, v_ref, a_ref) from the measured (q, dq) in `mode`."""
        if mode is CommandMode.POSITION:
            return self.positions(q_ref)
        if mode is CommandMode.VELOCITY:
            kp = KP_VELOCITY_1_S
            return self.velocities([v + kp * (r - x) for v, r, x in zip(v_ref, q_ref, q, strict=True)])
        w = HOLD_OMEGA_RAD_S
        kp, kd = w * w, 2.0 * w
        acc = [
            a + kp * (r - x) + kd * (v - dx)
            for a, r, x, v, dx in zip(a_ref, q_ref, q, v_ref, dq, strict=True)
        ]
        tau = pin.rnea(
            self.model.model,
            self._data,
            np.asarray(q, dtype=np.float64),
            np.asarray(dq, dtype=np.float64),
            np.asarray(acc, dtype=np.float64),
        ).tolist()
        lim = self._tau_max
        return self.currents([min(max(t, -m), m) for t, m in zip(tau, lim, strict=True)])
