"""The one arm-dynamics core of every simulated arm: the `sim` backend's, and through it the
plant process's, the CiA 402 drive simulator's and the UR controller simulator's; and the
Dynamixel servo simulator's.

Pinocchio forward dynamics (ABA) under the motors' torques, viscous friction, Coulomb friction
(and engaged holding brakes, as more of it) as a velocity-level projection so that a joint really
sticks when the torques on it are weaker, semi-implicit Euler; optionally hard stops at the URDF's
limits (an inelastic stop, where a real arm rests on its frame) and the motors' reflected rotor
inertia (armature). The caller owns time and the motors: `step(tau_motor_nm, h_s)` advances by
`h_s` with those torques held; `refresh_inertia()` when the pose has moved (the friction's reach
uses the diagonal of M⁻¹, which changes slowly with the pose).

In place on numpy arrays: no allocation per step.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from orccadd.model import RobotModel
from orccadd.state import FloatArray

# (q, dq) -> the external joint torques (N.m), or None when nothing touches the arm
ExternalTorque = Callable[[FloatArray, FloatArray], "FloatArray | None"]


class ArmDynamics:
    def __init__(
        self,
        model: RobotModel,
        q0_rad: FloatArray,
        *,
        viscous_nm_s_rad: FloatArray,
        coulomb_nm: FloatArray,
        armature_kg_m2: FloatArray | None = None,
        hard_stops: bool = False,
    ) -> None:
        n = model.dof
        self.pin_model = model.model
        if armature_kg_m2 is not None:  # the rotors' inertia on the joints: a model of its own
            self.pin_model = model.model.copy()
            self.pin_model.armature = np.maximum(np.asarray(self.pin_model.armature), armature_kg_m2)
        self.data = self.pin_model.createData()
        self.viscous = np.array(viscous_nm_s_rad, dtype=np.float64)
        self.coulomb = np.array(coulomb_nm, dtype=np.float64)
        self.holding_nm = np.zeros(n)  # more Coulomb torque, per joint: engaged holding brakes
        self.q_lo = np.asarray(self.pin_model.lowerPositionLimit, dtype=np.float64).copy()
        self.q_hi = np.asarray(self.pin_model.upperPositionLimit, dtype=np.float64).copy()
        self.hard_stops = hard_stops
        q0 = np.asarray(q0_rad, dtype=np.float64)
        self.q: FloatArray = np.clip(q0, self.q_lo, self.q_hi) if hard_stops else q0.copy()
        self.dq: FloatArray = np.zeros(n)
        self.minv_diag = np.ones(n)
        self._tau = np.zeros(n)
        self._tmp = np.zeros(n)
        self._dv = np.zeros(n)
        self._stuck = np.zeros(n, dtype=np.bool_)
        # the world's joint torques at (q, dq) (a contact's J^T W), at every step; None: nothing
        # touches the arm (the function may return None too)
        self.external: ExternalTorque | None = None
        self.refresh_inertia()

    @property
    def dof(self) -> int:
        return len(self.q)

    def refresh_inertia(self) -> None:
        """The diagonal of M⁻¹ at the current pose (the friction's reach in one step)."""
        pin.computeMinverse(self.pin_model, self.data, self.q)
        np.copyto(self.minv_diag, np.diag(self.data.Minv))

    def gravity_nm(self) -> FloatArray:
        """g(q): the joint torques that hold the arm where it is (Pinocchio's array)."""
        g: FloatArray = pin.computeGeneralizedGravity(self.pin_model, self.data, self.q)
        return g

    def step(self, tau_motor_nm: FloatArray, h_s: float) -> None:
        """Advance by `h_s` with the motors' joint torques `tau_motor_nm` held."""
        q, dq, tau, tmp = self.q, self.dq, self._tau, self._tmp
        np.multiply(self.viscous, dq, out=tau)
        np.subtract(tau_motor_nm, tau, out=tau)
        ext = self.external(q, dq) if self.external is not None else None
        if ext is not None:
            tau += ext
        ddq = pin.aba(self.pin_model, self.data, q, dq, tau)
        np.multiply(ddq, h_s, out=tmp)
        dq += tmp
        # Coulomb friction and brakes as the velocity change they can remove in this step
        dv, stuck = self._dv, self._stuck
        np.add(self.coulomb, self.holding_nm, out=dv)
        dv *= self.minv_diag
        dv *= h_s
        np.abs(dq, out=tmp)
        np.less_equal(tmp, dv, out=stuck)
        np.sign(dq, out=tmp)
        tmp *= dv
        dq -= tmp
        np.putmask(dq, stuck, 0.0)
        np.multiply(dq, h_s, out=tmp)
        q += tmp
        if self.hard_stops:
            self._stop_at_limits()

    def _stop_at_limits(self) -> None:
        """A joint past a limit rests on it, its velocity into the stop gone."""
        q, dq = self.q, self.dq
        below, above = q < self.q_lo, q > self.q_hi
        if below.any():
            np.putmask(q, below, self.q_lo)
            np.putmask(dq, below & (dq < 0.0), 0.0)
        if above.any():
            np.putmask(q, above, self.q_hi)
            np.putmask(dq, above & (dq > 0.0), 0.0)
