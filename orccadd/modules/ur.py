"""A UR controller's own behaviours, asked tick by tick: force mode and freedrive; and the tool
(payload and TCP) a task sets at its start.

Each module's output is wired to the `ur_rtde` resource's command of the same name
(`ctl.force_mode -> arm.force_mode`): the controller runs the behaviour while a task writes it,
and the resource ends it (force_mode_stop, end_freedrive_mode) in the first tick nothing does,
holding the arm where it then is. Element 0 of each command is the tick's time: what a task
stopped writing is never taken for a request.
"""

from __future__ import annotations

import numpy as np

from orccadd.drivers.ur.behaviours import (
    FORCE_MODE,
    FORCE_MODE_SIZE,
    FORCE_MODE_UNIT,
    FREEDRIVE,
    FREEDRIVE_SIZE,
    FREEDRIVE_UNIT,
    TOOL,
    TOOL_SIZE,
    TOOL_UNIT,
)
from orccadd.modules.base import Kernel, KernelModule, ModuleContext, register

ZERO6 = np.zeros(6)
# the controller's own bounds (UR's e-Series defaults): what no task may ask for; a robot
# config's force_mode_max_* narrow them, checked by the resource in the tick
WRENCH_BOUNDS = (np.array([-150.0] * 3 + [-50.0] * 3), np.array([150.0] * 3 + [50.0] * 3))
POSE_BOUNDS = (np.array([-5.0] * 3 + [-2 * np.pi] * 3), np.array([5.0] * 3 + [2 * np.pi] * 3))


@register("ur_force_mode")
class UrForceMode(KernelModule):
    """URScript's force_mode: along and about the compliant axes of the task frame (`selection`
    1), the arm moves so that the wrench it applies to its surroundings becomes `wrench_n_nm`,
    at most at `limits` (m/s and rad/s on those axes); the other axes keep their pose. `frame_type`
    as URScript's: 1 the frame's z toward the TCP, 2 the task frame as given (base frame pose), 3
    its x along the TCP's motion."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.out = self.add_output(FORCE_MODE, (FORCE_MODE_SIZE,), FORCE_MODE_UNIT)
        self.frame = self.add_parameter("task_frame", ZERO6, bounds=POSE_BOUNDS, unit="m|rad", shape=(6,))
        self.selection = self.add_parameter(
            "selection", np.array([0, 0, 1, 0, 0, 0]), bounds=(0, 1), unit="1", shape=(6,), integer=True
        )
        self.wrench = self.add_parameter(
            "wrench_n_nm", ZERO6, bounds=WRENCH_BOUNDS, unit="N|N.m", shape=(6,), tunable=True
        )
        self.frame_type = self.add_parameter("frame_type", 2, bounds=(1, 3), unit="1", integer=True)
        self.limits = self.add_parameter(
            "limits",
            np.array([0.1] * 3 + [0.5] * 3),
            bounds=(0.0, 3.2),
            unit="m/s|rad/s",
            shape=(6,),
            tunable=True,
        )

    def kernel(self) -> Kernel:
        frame, sel, wrench = self.frame.value, self.selection.value, self.wrench.value
        ftype, limits = self.frame_type.value, self.limits.value

        def force_mode(t_s: float) -> tuple[list[float]]:
            return ([t_s, *frame.tolist(), *sel.tolist(), *wrench.tolist(), float(ftype), *limits.tolist()],)

        return force_mode


@register("ur_freedrive")
class UrFreedrive(KernelModule):
    """URScript's freedrive_mode: the arm follows a hand pushing it along and about the
    `free_axes` (1: free) of the `feature` frame (a base-frame pose), and holds the others."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.out = self.add_output(FREEDRIVE, (FREEDRIVE_SIZE,), FREEDRIVE_UNIT)
        self.free = self.add_parameter(
            "free_axes", np.ones(6), bounds=(0, 1), unit="1", shape=(6,), integer=True
        )
        self.feature = self.add_parameter("feature", ZERO6, bounds=POSE_BOUNDS, unit="m|rad", shape=(6,))

    def kernel(self) -> Kernel:
        free, feature = self.free.value, self.feature.value

        def freedrive(t_s: float) -> tuple[list[float]]:
            return ([t_s, *free.tolist(), *feature.tolist()],)

        return freedrive


@register("ur_tool")
class UrTool(KernelModule):
    """The tool the arm carries while this task runs, set on the controller in the task's first
    tick (URScript set_payload and set_tcp): the payload's mass and centre of gravity (flange
    frame; the controller's gravity compensation and its collision detection use them) and the
    TCP (the pose of the tool point in the flange frame: actual_TCP_pose, force mode's frame).
    The resource checks the mass against the arm's rated payload and the controller checks it
    again; either refusal is a type 3 and nothing is sent. The tool stays set after the task, until
    another task sets one (a part in the gripper is still there): after a reset the resource sends
    it again."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self.out = self.add_output(TOOL, (TOOL_SIZE,), TOOL_UNIT)
        self.mass = self.add_parameter("payload_kg", 0.0, bounds=(0.0, 35.0), unit="kg", required=True)
        self.cog = self.add_parameter("payload_cog_m", np.zeros(3), bounds=(-1.0, 1.0), unit="m", shape=(3,))
        self.tcp = self.add_parameter("tcp_m_rad", ZERO6, bounds=POSE_BOUNDS, unit="m|rad", shape=(6,))

    def kernel(self) -> Kernel:
        mass, cog, tcp = self.mass.value, self.cog.value, self.tcp.value  # read each tick: a tune or
        # a `configure` after the kernel was made changes them in place

        def set_tool(t_s: float) -> tuple[list[float]]:
            return ([t_s, float(mass), *cog.tolist(), *tcp.tolist()],)

        return set_tool
