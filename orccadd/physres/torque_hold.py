"""Holding an arm in torque where it is: what a torque task sends while it waits for its
preconditions after a switch (`RobotTask.continue_from`), and what the UR backend sends on a
torque tick without a command (its controller leaves torque control without one every cycle)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.model import RobotModel
from orccadd.state import FloatArray, JointState

HOLD_KP_S2, HOLD_KD_S = 400.0, 40.0  # critically damped at 20 rad/s


class TorqueHold:
    """[g(q) +] M(q)·(kp·(q_hold − q) − kd·q̇), q_hold latched at the first update after `release`:
    the arm decelerates to rest there and stays. `gravity`: False where the device adds it (UR's
    direct torque). Not clamped: the caller sends it through the resource's limits."""

    def __init__(self, model: RobotModel, gravity: bool = True) -> None:
        self.model = model
        self.gravity = gravity
        self.data = model.new_data()
        self.q_rad: FloatArray | None = None

    def release(self) -> None:
        """The next `update` holds where the arm is then."""
        self.q_rad = None

    def update(self, st: JointState, out: FloatArray) -> None:
        if self.q_rad is None:
            self.q_rad = st.q_rad.copy()
        m, data, q = self.model.model, self.data, st.q_rad
        mass = pin.crba(m, data, q)
        mass = np.triu(mass) + np.triu(mass, 1).T  # crba fills the upper triangle
        acc = HOLD_KP_S2 * (self.q_rad - q) - HOLD_KD_S * st.dq_rad_s
        out[:] = mass @ acc
        if self.gravity:
            out += pin.computeGeneralizedGravity(m, data, q)
