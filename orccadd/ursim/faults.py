"""The simulator's control channel: faults injected, state asked, from any process.

A TCP port on 127.0.0.1 (printed in the simulator's ready line) takes one JSON object per line
and answers one per line, `{"ok": true, ...}` or `{"ok": false, "error": "..."}`:

    {"inject": "protective_stop"}                      (optional "reason")
    {"inject": "emergency_stop"}
    {"inject": "emergency_stop_release"}
    {"inject": "stream_stall", "duration_s": 1.0}
    {"inject": "drop_connection", "ports": "rtde"}    (rtde | dashboard | script | all)
    {"inject": "controller_restart", "down_s": 1.0}

The world and the I/O (`simulator.UrSimulator.inject`; `world.World`):

    {"inject": "wall", "point_m": [x, y, z], "normal": [nx, ny, nz], "stiffness_n_m": 5000}
        (optional "damping_n_s_m", 100 by default): a plane in the base frame, `normal` out of
        it into free space; the TCP inside it is pushed out (the arm's dynamics and the F/T
        sensor feel it). One wall at a time: a new one replaces the old.
    {"inject": "wall_remove"}
    {"inject": "plane", "point_m": [...], "normal": [...], "stiffness_n_m": 5000}    (added; optional
        "damping_n_s_m", "friction", "viscous_friction_n_s_m": the simulated arm's planes)
    {"inject": "hole", "center_m": [...], "normal": [...], "radius_m": 0.01, "depth_m": 0.03,
        "stiffness_n_m": 5000}   a plane with a pocket in it (docs/simulators.md: the contact world)
    {"inject": "tool", "radius_m": 0.008}   the TCP a sphere of that radius (0: a point)
    {"inject": "clear_world"}   every plane and hole, the wall and the push removed
    {"inject": "push", "force_n": [fx, fy, fz], "torque_nm": [tx, ty, tz], "duration_s": 0.5}
        a wrench on the TCP (base frame) for that long: a hand on the tool
    {"inject": "digital_input", "index": 3, "value": true}               standard DI 0-7 (bits 0-7)
    {"inject": "configurable_digital_input", "index": 0, "value": true}  CI 0-7 (bits 8-15)
    {"inject": "tool_digital_input", "index": 1, "value": true}          TDI 0-1 (bits 16-17)
    {"inject": "ft_noise", "force_n": 0.5, "torque_nm": 0.02, "seed": 1}  sensor noise (std)
    {"inject": "speed_slider", "fraction": 0.5}   the teach pendant's speed slider, set by hand
    {"status": true}   -> modes, program, joint positions, cycles, connections, ports, the
                          wall, tcp_force, external_wrench, motion, payload_kg, I/O bits

The protocol is every simulator's (`orccadd.runtime.sim_control`); `process.UrSimProcess.inject()`
and `.status()` send these for Python callers.
"""

from __future__ import annotations

import logging

from orccadd.runtime.sim_control import Injection
from orccadd.ursim.simulator import UrSimulator

log = logging.getLogger("orccadd.ursim")


def inject(sim: UrSimulator, req: Injection) -> None:
    """One injection: the controller is one device (no `device`), the fault's parameters as
    keyword arguments."""
    if req.device is not None:
        raise ValueError('a UR fault concerns the whole controller: no "device"')
    sim.inject(req.fault, **req.params)
