"""The speed slider and the speed scaling it gives the controller's own trajectories.

RTDE inputs `speed_slider_mask` (bit 0: "use speed_slider_fraction to set the speed slider") and
`speed_slider_fraction` (0-1), which ur_rtde's `RTDEIOInterface.setSpeedSlider` writes, set the
slider; it keeps its value while the mask is 0. The outputs: `target_speed_fraction` (the
slider) and `speed_scaling` (the scaling the trajectories run at: the slider's value reached
at `RATE_1_S`, so that a motion under way slows without a jump; 0 while no program plays).

What it scales: the planned motions (movej, speedj) run in scaled time (speed × s, acceleration
× s²). Not scaled: servoj (it follows the client's stream, which is the client's to slow down
by reading speed_scaling, as UR's ROS driver does), direct torque, force mode and freedrive
(their speeds are their own limits), and stops.
"""

from __future__ import annotations

from orccadd.ursim.robot_state import RobotState

RATE_1_S = 2.0  # change of the scaling per second (full range in 0.5 s)


class SpeedScaling:
    """The slider's value (`slider`) and the scaling reached (`scaling`), one step a cycle."""

    def __init__(self) -> None:
        self.slider = 1.0
        self.scaling = 1.0

    def reset(self) -> None:
        self.slider = self.scaling = 1.0

    def step(self, state: RobotState, h_s: float) -> float:
        """Take the slider from the inputs, move the scaling towards it; the scaling."""
        if state.speed_slider_mask & 1:
            self.slider = min(max(float(state.speed_slider_fraction), 0.0), 1.0)
        room = RATE_1_S * h_s
        self.scaling += min(max(self.slider - self.scaling, -room), room)
        return self.scaling
