"""The controller's force side: the flange sensor read every cycle, the contact history behind
`tool_contact`, force mode's gain and damping, and the motions of force mode and freedrive.

The control script calls it (`control_script.ControlScript`), the controller's cycle feeds it
(`measure`, once per cycle under the controller's lock, after the arm's dynamics advanced).
"""

from __future__ import annotations

import math

import numpy as np

from orccadd.state import FloatArray
from orccadd.ursim.arm import UrArm
from orccadd.ursim.force_mode import (
    D_FULL_1_S,
    FREEDRIVE_DAMPING_1_S,
    FREEDRIVE_INERTIA_KG_M2,
    FREEDRIVE_MASS_KG,
    Admittance,
    ForceModeArgs,
    force_mode_error,
    freedrive_args,
    freedrive_status,
)
from orccadd.ursim.ft_sensor import FtSensor
from orccadd.ursim.robot_state import RobotState
from orccadd.ursim.tool_contact import ContactHistory

# URScript's defaults (ur_rtde's script sets 0.5 and 0.025 when it starts)
DEFAULT_GAIN_SCALING = 1.0
DEFAULT_DAMPING = 0.005
GAIN_SCALING_RANGE = (0.0, 2.0)
DAMPING_RANGE = (0.0, 1.0)
FREEDRIVE_NAMES = ("freedrive", "teach_mode")


class ForceControl:
    """Sensor, contact detection and admittance motions of one controller."""

    def __init__(self, arm: UrArm, state: RobotState) -> None:
        self.arm, self.state = arm, state
        self.sensor = FtSensor(state.actual_tcp_force, state.ft_raw_wrench)
        self.contacts = ContactHistory()
        self.external = np.zeros(6)  # the true external wrench at the TCP (base frame)
        self._cog_from_tcp = np.zeros(3)  # the payload's centre of gravity from the TCP (base)
        self.reset()

    def reset(self) -> None:
        """At boot: no offset, URScript's default gain and damping, no contact history."""
        self.sensor.reset()
        self.contacts.clear()
        self.gain_scaling = DEFAULT_GAIN_SCALING
        self.damping = DEFAULT_DAMPING

    # ---- every cycle ----------------------------------------------------------------------
    def measure(self) -> None:
        """Read the sensor at the arm's measured state; record the reading for tool_contact."""
        arm, s = self.arm, self.state
        arm.external_wrench(arm.q_rad, arm.dq_rad_s, self.external)
        cog_from_tcp = self._cog_from_tcp
        if s.payload_kg:
            tcp = arm.tcp(arm.q_rad)
            flange = tcp * arm.tcp_offset.inverse()
            cog_from_tcp[:] = flange.act(np.asarray(s.payload_cog)) - tcp.translation
        self.sensor.measure(self.external, s.payload_kg, cog_from_tcp)
        self.contacts.record(s.actual_tcp_force)

    # ---- script functions -----------------------------------------------------------------
    def zero_ftsensor(self) -> None:
        self.sensor.zero()

    def set_gain_scaling(self, scaling: float) -> str:
        """force_mode_set_gain_scaling: '' or why refused (a runtime error)."""
        lo, hi = GAIN_SCALING_RANGE
        if not (math.isfinite(scaling) and lo <= scaling <= hi):
            return f"force_mode_set_gain_scaling: scaling (={scaling:g}) must be in [{lo:g}, {hi:g}]"
        self.gain_scaling = scaling
        return ""

    def set_damping(self, damping: float) -> str:
        """force_mode_set_damping: '' or why refused (a runtime error)."""
        lo, hi = DAMPING_RANGE
        if not (math.isfinite(damping) and lo <= damping <= hi):
            return f"force_mode_set_damping: damping (={damping:g}) must be in [{lo:g}, {hi:g}]"
        self.damping = damping
        return ""

    def force_mode(self, args: ForceModeArgs) -> Admittance | str:
        """A force mode motion for `args`, or why the controller refuses them."""
        why = force_mode_error(args)
        if why:
            return why
        s = self.state
        return Admittance(
            "force_mode",
            self.arm,
            s.actual_tcp_force,
            s.actual_tcp_speed,
            args,
            self.gain_scaling,
            self.damping * D_FULL_1_S,
        )

    def freedrive(
        self, free_axes: tuple[int, ...], feature: tuple[float, ...], name: str
    ) -> Admittance | str:
        """freedrive_mode(free_axes, feature) (`name` "freedrive") or teach_mode()."""
        if any(f not in (0, 1) for f in free_axes):
            return f"freedrive_mode: freeAxes (={list(free_axes)}) must hold 0 or 1"
        if not all(math.isfinite(v) for v in feature):
            return "freedrive_mode: feature must be finite"
        s = self.state
        return Admittance(
            name,
            self.arm,
            s.actual_tcp_force,
            s.actual_tcp_speed,
            freedrive_args(free_axes, feature),
            1.0,
            FREEDRIVE_DAMPING_1_S,
            (FREEDRIVE_MASS_KG, FREEDRIVE_INERTIA_KG_M2),
        )

    def freedrive_status(self) -> int:
        return freedrive_status(self.arm, self.arm.q_rad)

    def tool_contact(self, direction: FloatArray) -> int:
        return self.contacts.steps_in_contact(direction)
