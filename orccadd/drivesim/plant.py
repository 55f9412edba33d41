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
from orccadd.physres.sim import SimulatedArm
from orccadd.types import CommandMode


class Drive(IntEnum):
    """What a joint's drive does with its motor, per joint."""

    OFF = 0  # power stage off, holding brake engaged
    TORQUE = 1  # torque reference (N·m at the joint)
    VELOCITY = 2  # velocity servo to a reference (rad/s)
    POSITION = 3  # position servo to a reference (rad) with velocity feed-forward


# The simulator integrates at least every 5 ms (its bus poll); a gap longer than this means its
# process did not run (a VM or scheduler stall): the simulated world pauses for the excess rather
# than integrate the drives' last references over it (real drives run on; a controller stalled
# that long has faulted anyway). Counted in `paused_s`.
PAUSE_AFTER_S = 0.02


class DriveTrainArm(SimulatedArm):
    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        n = self.dof
        self.drive = np.zeros(n, dtype=np.int64)  # Drive per joint
        self.torque_ref = np.zeros(n)
        self.velocity_ref = np.zeros(n)
        self.position_ref = np.zeros(n)
        self._err = np.zeros(n)
        # per joint, from `drive` at the start of each integration (the modes are held in it):
        self._torque_on = np.zeros(n)  # 1 where the torque reference applies
        self._gravity_on = np.zeros(n)  # 1 where the drive's servo compensates gravity
        self._kp_on = np.zeros(n)  # position gain, 0 unless POSITION
        self._kd_on = np.zeros(n)  # velocity gain: kd (POSITION), 4 kd (VELOCITY), else 0
        self._brake_on = np.zeros(n)  # the holding brake's torque where the power stage is off
        self.paused_s = 0.0
        self.configure()
        self.activate(CommandMode.TORQUE)  # the base class's lifecycle: powered, per-joint below

    def step_to(self, t_s: float) -> None:
        """Integrate the dynamics up to `t_s` (wall time, seconds) with the references held."""
        if self.t_sim_s is None:
            self.t_sim_s = t_s
        if t_s - self.t_sim_s > PAUSE_AFTER_S:
            self.paused_s += t_s - self.t_sim_s - PAUSE_AFTER_S
            self.t_sim_s = t_s - PAUSE_AFTER_S
        d = self.drive
        pos, vel = d == POSITION, d == VELOCITY
        self._torque_on[:] = d == TORQUE
        self._gravity_on[:] = pos | vel
        self._kp_on[:] = self._kp * pos
        self._kd_on[:] = self._kd * pos + self._kd_velocity * vel
        self._brake_on[:] = self._brake * (d == OFF)  # holding brakes engaged
        self._advance_to(t_s)

    def _motor_torque(self, out: np.ndarray) -> None:
        """torque_on·τ_ref + gravity_on·g(q) + kp_on·(q_ref − q) + kd_on·(v_ref − dq), saturated."""
        err = self._err
        np.multiply(pin.computeGeneralizedGravity(self._pin, self._data, self.q), self._gravity_on, out=out)
        np.subtract(self.position_ref, self.q, out=err)
        err *= self._kp_on
        out += err
        np.subtract(self.velocity_ref, self.dq, out=err)
        err *= self._kd_on
        out += err
        np.multiply(self.torque_ref, self._torque_on, out=err)
        out += err
        np.clip(out, self._neg_tau_max, self.model.tau_max_nm, out=out)

    def _holding_torque(self, out: np.ndarray) -> None:
        out[:] = self._brake_on


OFF, TORQUE, VELOCITY, POSITION = (int(m) for m in Drive)  # plain ints for the per-step arithmetic
