"""Image-based visual servoing (IBVS) on point features, a camera on the tool (eye in hand).

The camera's frame is the tool's (`[tool]`: its z the optical axis, x and y the image's u and
v). A feature is a point's normalised image coordinates (x, y) = (X/Z, Y/Z) in that frame (a
pixel's (u − c_u)/f_u, (v − c_v)/f_v: the camera's intrinsics are the sensor's business). For
FEATURES points, with e = s − s* the feature error, the camera's twist is

    v_c = −λ·L⁺·e,   L = ½·(L(s, Z*) + L(s*, Z*))    (Malis' mean of the current and desired)

with each point's interaction matrix (Chaumette and Hutchinson, 2006)

    L(x, y, Z) = [ −1/Z   0    x/Z   x·y     −(1 + x²)   y ]
                 [  0   −1/Z   y/Z   1 + y²  −x·y       −x ]

and Z* (`depth_m`) the target's depth at the goal, for every point (an estimate: IBVS converges
with a coarse one). The twist, on the base's axes, moves a desired pose that `resolved_rate`
follows; while the target is not seen (`visible` below 1) the desired pose holds still.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from orccadd.kinematics import ToolKinematics, clip_norm, quaternion_of
from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register
from orccadd.modules.cartesian import TWIST_UNIT
from orccadd.state import JointState

FEATURES = 4  # the points of a target (a square's corners: the classic IBVS target)
Outputs = tuple[list[float], list[float], list[float], float]


def interaction_matrix(s: np.ndarray, depth_m: float) -> np.ndarray:
    """The 2N×6 interaction matrix of N point features `s` (x1, y1, x2, ...) at depth Z."""
    n = len(s) // 2
    lm = np.zeros((2 * n, 6))
    inv_z = 1.0 / depth_m
    for i in range(n):
        x, y = s[2 * i], s[2 * i + 1]
        lm[2 * i] = (-inv_z, 0.0, x * inv_z, x * y, -(1.0 + x * x), y)
        lm[2 * i + 1] = (0.0, -inv_z, y * inv_z, 1.0 + y * y, -x * y, -x)
    return lm


@register("image_servo")
class ImageServo(KernelModule):
    """IBVS on four point features (FEATURES; see the module's doc): `features` and `visible` in (from
    a camera), the desired pose and twist out (to `resolved_rate`), and the feature error's norm
    (`feature_error`, for a watcher: converged below a threshold)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.add_input("features", (2 * FEATURES,), "1")
        self.add_input("visible", (1,), "1")  # a resource's one-number signal: arm.target_visible
        self.add_output("position_des_m", (3,), "m")
        self.add_output("orientation_des", (4,), "1")
        self.add_output("twist_des", (6,), TWIST_UNIT)
        self.add_output("feature_error", (), "1")
        self.goal = self.add_parameter(
            "features_des",
            [-0.1, -0.1, 0.1, -0.1, 0.1, 0.1, -0.1, 0.1],
            bounds=(-2.0, 2.0),
            unit="1",
            shape=(2 * FEATURES,),
            required=True,
            per_joint=True,
            element="coordinate",
        )
        self.gain = self.add_parameter("gain", 1.0, bounds=(0.0, 20.0), unit="1/s", tunable=True)
        self.depth = self.add_parameter("depth_m", 0.3, bounds=(0.01, 10.0), unit="m", tunable=True)
        self.vmax = self.add_parameter("max_speed_m_s", 0.1, bounds=(0.0, 1.0), unit="m/s", tunable=True)
        self.wmax = self.add_parameter("max_speed_rad_s", 0.5, bounds=(0.0, 3.0), unit="rad/s", tunable=True)
        self._kin = ToolKinematics(ctx.model)
        self._dt = ctx.period_s
        self._p = np.zeros(3)
        self._r = np.eye(3)

    def start(self, state: JointState) -> None:
        pose = self._kin.pose(state.q_rad)
        self._p, self._r = pose.translation.copy(), pose.rotation.copy()

    def kernel(self) -> Kernel:
        dt = self._dt

        def servo(t_s: float, features: list[float], visible: list[float]) -> Outputs:
            s, s_star = np.asarray(features), self.goal.value
            e = s - s_star
            error = float(np.linalg.norm(e))
            if visible[0] < 1.0 or not np.isfinite(error):  # nothing to servo on: hold still
                return (self._p.tolist(), quaternion_of(self._r), [0.0] * 6, error)
            z = float(self.depth.value)
            lm = 0.5 * (interaction_matrix(s, z) + interaction_matrix(s_star, z))
            v_c = -float(self.gain.value) * (np.linalg.pinv(lm) @ e)
            v_c[:3] = clip_norm(v_c[:3], float(self.vmax.value))
            v_c[3:] = clip_norm(v_c[3:], float(self.wmax.value))
            r = self._r
            v, w = r @ v_c[:3], r @ v_c[3:]  # the camera's (the tool's) axes on the base's
            self._p = self._p + v * dt
            self._r = pin.exp3(w * dt) @ r
            return (self._p.tolist(), quaternion_of(self._r), v.tolist() + w.tolist(), error)

        return servo
