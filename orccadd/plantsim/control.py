"""The plant process's control channel: its contact world and its camera's scene changed, its
state asked, from a shell (`python -m orccadd.simctl 127.0.0.1:PORT ...`) or a test.

The protocol of every simulator (`orccadd.runtime.sim_control`: JSON lines on 127.0.0.1, the port
in the `sim_process` resource's details as `plant_control`; the plant has no device protocol of
its own, so this is the only way in besides the controller's shared memory):

    {"inject": "plane", "point_m": [x, y, z], "normal": [nx, ny, nz], "stiffness_n_m": 5000}
        optional "damping_n_s_m" (100), "friction" (Coulomb μ, 0), "viscous_friction_n_s_m" (0):
        a plane in the base frame, `normal` out of it into free space, added to the world; the
        parameters of the UR simulator's `wall`, and its law (`orccadd.physres.contact`)
    {"inject": "hole", "center_m": [x, y, z], "normal": [...], "radius_m": 0.01, "stiffness_n_m": 5000}
        optional "depth_m" (none: through), and the plane's optional ones: a plane through
        `center_m` with a round hole there, added to the world
    {"inject": "clear_world"}      every plane and hole removed
    {"inject": "occlude"}          an occluder before the camera: the target is not seen
    {"inject": "unocclude"}        the occluder taken away
    {"inject": "target", "points_m": [[x, y, z], ...]}
        the camera's target moved to these 4 points (base frame, in the features' order)
    {"status": true}   -> q_rad, dq_rad_s, devices (the arm: lifecycle and mode), world (its
                          shapes and the tool's radius), wrench (the sensor's last reading),
                          camera (its target, occluder and last image; null: no camera)

The camera's changes are refused when the arm has none (`[resource.settings.camera]`).

Several shapes may be in the world at once; the arm feels their sum (`ContactWorld`).
"""

from __future__ import annotations

import logging
import socket
import sys
import threading
from typing import Any

from orccadd.physres.sim import SimulatedArm
from orccadd.physres.sim_camera import CAMERA_CHANGES, change_camera
from orccadd.physres.sim_contact import WORLD_CHANGES, WRENCH, change_world
from orccadd.runtime import sim_control
from orccadd.runtime.sim_control import Injection
from orccadd.runtime.threads import ThreadGroup

log = logging.getLogger("orccadd.plantsim")
# what `inject` takes (the names `python -m orccadd.simctl --help` lists)
FAULTS = WORLD_CHANGES + CAMERA_CHANGES
JOIN_S = 2.0
SWITCH_INTERVAL_S = 0.0005  # the step waits at most this long for the interpreter


class PlantControl:
    """The control channel of one plant's arm, served by threads of its own (time-shared) until
    `close`."""

    def __init__(self, arm: SimulatedArm, port: int = 0) -> None:
        self.arm = arm
        self._lock = threading.Lock()  # one change of the world at a time
        self.socket = socket.create_server(("127.0.0.1", port))
        self.port: int = self.socket.getsockname()[1]
        self.threads = ThreadGroup("plantsim")
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self.threads.start(
            sim_control.serve, self.socket, self.inject, self.status, self.threads, name="control"
        )
        log.info("control 127.0.0.1:%d", self.port)

    def inject(self, req: Injection) -> None:
        """One change of the world or of the camera's scene (`ValueError` naming what is wrong)."""
        if req.fault not in FAULTS:
            raise ValueError(f"unknown fault {req.fault!r} (faults: {', '.join(FAULTS)})")
        if req.device is not None:
            raise ValueError('the plant is one arm: no "device"')
        with self._lock:
            if req.fault in CAMERA_CHANGES:
                change_camera(self.arm.camera, req.fault, req.params)
            else:
                change_world(self.arm.world, req.fault, req.params)
        part = "camera" if req.fault in CAMERA_CHANGES else "world"
        log.info("%s: %s %s", part, req.fault, req.params or "")

    def status(self) -> dict[str, Any]:
        arm = self.arm
        fault = arm.fault_message
        return {
            "q_rad": arm.q.tolist(),
            "dq_rad_s": arm.dq.tolist(),
            "devices": [
                sim_control.device("arm", f"{arm.lifecycle.name.lower()} {arm.mode.name.lower()}", fault)
            ],
            "world": arm.world.describe(),
            "wrench": arm.signals[WRENCH.name].tolist(),
            "camera": arm.camera.describe() if arm.camera is not None else None,
        }

    def close(self) -> None:
        self.socket.close()
        self.threads.join(JOIN_S)
