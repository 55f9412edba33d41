"""The arm behind the simulated drives: one Pinocchio simulation, each joint driven by its own
drive (torque off and braked, cyclic torque, or the drive's velocity / position servo).

It reuses `SimulatedArm`'s dynamics (ABA in fixed sub-steps, viscous and Coulomb friction,
torque saturation, servo gains from the reflected inertia); only the motor torque and the
brakes become per joint, because each CiA 402 drive switches its own power stage.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np
import pinocchio as pin

from orccadd.config.robot import RobotConfig
from orccadd.model import RobotModel
from orccadd.physres.base import CommandMode
from orccadd.physres.sim import SimulatedArm


class Drive(IntEnum):
    """What a joint's drive does with its motor, per joint."""

    OFF = 0  # power stage off, holding brake engaged
    TORQUE = 1  # torque reference (N·m at the joint)
    VELOCITY = 2  # velocity servo to a reference (rad/s)
    POSITION = 3  # position servo to a reference (rad) with velocity feed-forward


class DriveTrainArm(SimulatedArm):
    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        n = self.dof
        self.drive = np.zeros(n, dtype=np.int64)  # Drive per joint
        self.torque_ref = np.zeros(n)
        self.velocity_ref = np.zeros(n)
        self.position_ref = np.zeros(n)
        self._g = np.zeros(n)
        self._pos = np.zeros(n)
        self._vel = np.zeros(n)
        self.configure()
        self.activate(CommandMode.TORQUE)  # the base class's lifecycle: powered, per-joint below

    def step_to(self, t_s: float) -> None:
        """Integrate the dynamics up to `t_s` (wall time, seconds) with the references held."""
        if self.t_sim_s is None:
            self.t_sim_s = t_s
        self._advance_to(t_s)

    def _motor_torque(self, out: np.ndarray) -> None:
        d = self.drive
        self._g[:] = pin.computeGeneralizedGravity(self._pin, self._data, self.q)
        np.subtract(self.velocity_ref, self.dq, out=self._vel)
        np.subtract(self.position_ref, self.q, out=self._pos)
        pos = self._g + self._kp * self._pos + self._kd * self._vel
        vel = self._g + self._kd_velocity * self._vel
        out[:] = np.where(d == Drive.TORQUE, self.torque_ref, np.where(d == Drive.POSITION, pos, vel))
        out[d == Drive.OFF] = 0.0
        np.clip(out, self._neg_tau_max, self.model.tau_max_nm, out=out)

    def _update_friction(self, h: float) -> None:
        dv = self._dv_friction
        braked = self.drive == Drive.OFF
        np.add(self._coulomb, np.where(braked, self._brake, 0.0), out=dv)  # holding brakes
        dv *= self._minv_diag
        dv *= h
