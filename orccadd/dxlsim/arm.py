"""The arm the servos move: Pinocchio forward dynamics (ABA), semi-implicit Euler.

Each joint carries its servo's reflected rotor inertia (the model's armature), the gear train's
Coulomb friction (a velocity-level projection, so a joint with torque off really sticks when
gravity is weaker than the friction) and a little viscous friction. The joints end on hard
stops at the URDF's limits: an inelastic stop, where the real arm rests on its frame. Time is
the caller's: `step(tau, h)` advances by `h` with the joint torques `tau` held.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from orccadd.model import RobotModel

FloatArray = npt.NDArray[np.float64]


class ArmDynamics:
    def __init__(
        self,
        model: RobotModel,
        armature_kg_m2: FloatArray,
        friction_nm: FloatArray,
        viscous_nm_s_rad: FloatArray,
        q0_rad: FloatArray,
    ) -> None:
        self.pin_model = model.model.copy()
        self.pin_model.armature = np.maximum(np.asarray(self.pin_model.armature), armature_kg_m2)
        self.data = self.pin_model.createData()
        self.friction_nm = friction_nm.copy()
        self.viscous = viscous_nm_s_rad.copy()
        self.q_lo = np.asarray(self.pin_model.lowerPositionLimit, dtype=np.float64).copy()
        self.q_hi = np.asarray(self.pin_model.upperPositionLimit, dtype=np.float64).copy()
        self.q: FloatArray = np.clip(q0_rad.astype(np.float64), self.q_lo, self.q_hi)
        self.dq: FloatArray = np.zeros_like(self.q)
        self._minv_diag = np.ones_like(self.q)
        self._friction = [float(x) for x in friction_nm]
        self._lo = [float(x) for x in self.q_lo]
        self._hi = [float(x) for x in self.q_hi]
        self._steps_since_minv = 1 << 30

    @property
    def dof(self) -> int:
        return len(self.q)

    def step(self, tau_nm: list[float], h_s: float) -> None:
        """Advance by `h_s` with the joint torques `tau_nm` (N·m) held. Plain floats past ABA: six
        joints cost less as Python numbers than as numpy calls."""
        if self._steps_since_minv >= 10:  # the inertia changes slowly with the pose
            pin.computeMinverse(self.pin_model, self.data, self.q)
            self._minv_diag[:] = np.diag(self.data.Minv)
            self._steps_since_minv = 0
        self._steps_since_minv += 1
        tau = np.array(tau_nm, dtype=np.float64) - self.viscous * self.dq
        ddq = pin.aba(self.pin_model, self.data, self.q, self.dq, tau).tolist()
        q, dq = self.q.tolist(), self.dq.tolist()
        friction, minv = self._friction, self._minv_diag.tolist()
        lo, hi = self._lo, self._hi
        for j in range(len(q)):
            v = dq[j] + h_s * ddq[j]
            # Coulomb friction as the velocity change it can remove this step: sticks below it
            dv = friction[j] * minv[j] * h_s
            v = 0.0 if abs(v) <= dv else v - math.copysign(dv, v)
            x = q[j] + h_s * v
            if x < lo[j]:
                x, v = lo[j], max(v, 0.0)
            elif x > hi[j]:
                x, v = hi[j], min(v, 0.0)
            q[j], dq[j] = x, v
        self.q = np.array(q)
        self.dq = np.array(dq)
