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

`process.UrSimProcess.inject()` and `.status()` send these for Python callers.
"""

from __future__ import annotations

import json
import logging
import socket
from typing import Any

from orccadd.runtime.threads import ThreadGroup
from orccadd.ursim.simulator import UrSimulator

log = logging.getLogger("orccadd.ursim")


def handle_request(sim: UrSimulator, req: Any) -> dict[str, Any]:
    """The answer to one control request."""
    if not isinstance(req, dict):
        raise ValueError("a request is a JSON object")
    if "inject" in req:
        params = {k: v for k, v in req.items() if k != "inject"}
        sim.inject(str(req["inject"]), **params)
        return {"ok": True}
    if req.get("status"):
        return {"ok": True, **sim.status()}
    raise ValueError('a request has "inject" or "status"')


def serve_control(sim: UrSimulator, srv: socket.socket, threads: ThreadGroup) -> None:
    """Accept control clients (each in a thread of `threads`) until `srv` is closed."""
    while True:
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        threads.start(_client, sim, conn, name="control-client")


def _client(sim: UrSimulator, conn: socket.socket) -> None:
    with conn, conn.makefile("rwb") as f:
        for line in f:
            try:
                reply = handle_request(sim, json.loads(line))
            except (ValueError, TypeError) as e:
                reply = {"ok": False, "error": str(e)}
            f.write(json.dumps(reply).encode() + b"\n")
            f.flush()
