"""The simulator's control channel: faults injected, state asked, from any process.

A TCP port on 127.0.0.1 (printed in the simulator's ready line) takes one JSON object per line
and answers one per line, `{"ok": true, ...}` or `{"ok": false, "error": "..."}`:

    {"inject": "protective_stop"}                      (optional "reason")
    {"inject": "emergency_stop"}
    {"inject": "emergency_stop_release"}
    {"inject": "stream_stall", "duration_s": 1.0}
    {"inject": "drop_connection", "ports": "rtde"}    (rtde | dashboard | script | all)
    {"inject": "controller_restart", "down_s": 1.0}
    {"status": true}   -> modes, program, joint positions, cycles, connections, ports

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
