"""The device simulators' one control protocol (drive, servo and UR simulators; the plant process
has a shared-memory channel instead): JSON lines on a socket, one request per line, one reply per
line.

    {"inject": FAULT}                          a fault of the whole device
    {"inject": FAULT, "device": N}             of one device on the bus (node id, servo ID)
    {"inject": FAULT, ..., PARAM: VALUE}       with the fault's parameters (duration_s, rate, ...)
    {"status": true}

    {"ok": true, ...}  |  {"ok": false, "error": "..."}

Every status reply has the plant's `q_rad` and `dq_rad_s` and `devices`, a list of
`{"id", "state", "fault"}` (the device's state in its own protocol's words, its fault or ""),
then what the simulator adds of its own. `orccadd.simproc.SimulatorProcess` is the client.
Which simulators share protocol code with their driver, and why: docs/simulators.md.
"""

from __future__ import annotations

import json
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from orccadd.runtime.threads import ThreadGroup

MAX_LINE = 4096


@dataclass(frozen=True)
class Injection:
    fault: str
    device: int | None = None
    params: dict[str, Any] = field(default_factory=dict)


def parse_request(line: bytes) -> Injection | None:
    """An injection, or None for a status request; `ValueError` for anything else."""
    req = json.loads(line)
    if not isinstance(req, dict):
        raise ValueError("a request is a JSON object")
    if "inject" in req:
        fault = req["inject"]
        if not isinstance(fault, str):
            raise ValueError('"inject" names a fault (a string)')
        device = req.get("device")
        if device is not None and (isinstance(device, bool) or not isinstance(device, int)):
            raise ValueError('"device" is a device number (an integer)')
        params = {k: v for k, v in req.items() if k not in ("inject", "device")}
        return Injection(fault, device, params)
    if req.get("status") is True and len(req) == 1:
        return None
    raise ValueError('a request is {"inject": FAULT, ...} or {"status": true}')


Inject = Callable[[Injection], None]
Status = Callable[[], dict[str, Any]]


def answer(line: bytes, inject: Inject, status: Status) -> dict[str, Any]:
    """The reply to one request line: the simulator's `inject` or `status` called."""
    try:
        req = parse_request(line)
        if req is None:
            return {"ok": True, **status()}
        inject(req)
        return {"ok": True}
    except (ValueError, TypeError, KeyError) as e:
        return {"ok": False, "error": str(e)}


def device(id: int | str, state: str, fault: str = "") -> dict[str, Any]:
    """One entry of a status reply's `devices`."""
    return {"id": id, "state": state, "fault": fault}


def serve(
    srv: socket.socket,
    inject: Inject,
    status: Status,
    threads: ThreadGroup,
) -> None:
    """Accept control clients on `srv` (each served by a thread of `threads`) until the group
    stops or `srv` is closed."""
    srv.settimeout(0.2)
    while not threads.stopping.is_set():
        try:
            conn, _ = srv.accept()
        except TimeoutError:
            continue
        except OSError:
            return  # closed
        threads.start(_client, conn, inject, status, name="control-client")


def _client(conn: socket.socket, inject: Inject, status: Status) -> None:
    with conn, conn.makefile("rwb") as f:
        for line in f:
            reply = answer(line[:MAX_LINE], inject, status)
            f.write(json.dumps(reply).encode() + b"\n")
            f.flush()
