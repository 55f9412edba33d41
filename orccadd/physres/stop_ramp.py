"""The safe stop's deceleration for every backend that streams its own stop (Dynamixel, UR): a
reference that leaves the commanded or measured state at the stop and slows every joint together
at the configured deceleration (the path is kept: the joints' speeds shrink by one factor), then
stands still. The backend streams it as goals (positions, or velocities and torques that track
it), then holds its end. Backends whose device ramps by itself (CiA 402 quick stop) or whose plant
is simulated do not use it.

Pure arithmetic on lists, one step per tick; time is the tick's.
"""

from __future__ import annotations

from collections.abc import Sequence


class StopRamp:
    def __init__(self, dof: int) -> None:
        self.q_rad = [0.0] * dof
        self.dq_rad_s = [0.0] * dof
        self.ddq_rad_s2 = [0.0] * dof
        self.t_s = 0.0

    def start(self, q_rad: Sequence[float], dq_rad_s: Sequence[float], t_s: float) -> None:
        self.q_rad[:] = q_rad
        self.dq_rad_s[:] = dq_rad_s
        self.ddq_rad_s2[:] = [0.0] * len(self.ddq_rad_s2)
        self.t_s = t_s

    def hold(self, q_rad: Sequence[float], t_s: float) -> None:
        """Stand still at `q_rad`."""
        self.start(q_rad, [0.0] * len(q_rad), t_s)

    @property
    def done(self) -> bool:
        return not any(self.dq_rad_s)

    def step(self, t_s: float, deceleration_rad_s2: float) -> None:
        """Advance to `t_s`: speeds down by `deceleration_rad_s2 · dt` (the fastest joint's; the
        others in proportion), positions on by the mean speed."""
        dt = max(0.0, t_s - self.t_s)
        self.t_s = t_s
        v = self.dq_rad_s
        peak = max(map(abs, v), default=0.0)
        if peak == 0.0:
            self.ddq_rad_s2[:] = v
            return
        scale = max(0.0, peak - deceleration_rad_s2 * dt) / peak
        for j, vj in enumerate(v):
            new = vj * scale
            self.q_rad[j] += 0.5 * (vj + new) * dt
            self.ddq_rad_s2[j] = -deceleration_rad_s2 * vj / peak if scale > 0.0 else 0.0
            v[j] = new
