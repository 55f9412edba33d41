"""The orccadctl protocol: newline-delimited JSON over the daemon's Unix socket.

Request:  {"id": <any>, "cmd": "<command>", "args": {...}}            (one line, ≤ 64 KiB)
Reply:    {"id": <same>, "ok": true, "result": {...}}
          {"id": <same>, "ok": false, "error": "<what and why>"}
Streams (`monitor`, `events` with follow): several `{"id", "ok": true, "stream": {...}}` lines,
then a final reply; the client may close the connection at any time.

Every request is checked here against `COMMANDS` (argument names, types, required ones) before
anything else happens; a malformed, oversized, unknown or unauthorised request gets an error
reply and changes nothing. docs/protocol.md lists the commands.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

MAX_LINE = 65536
READ, CONTROL = "read", "control"

NUMBER = (int, float)


@dataclass(frozen=True)
class Spec:
    role: str
    args: dict[str, tuple[type, ...]]
    required: tuple[str, ...] = ()
    forward: bool = True  # executed by the real-time process (else by the command daemon)
    doc: str = ""


COMMANDS: dict[str, Spec] = {
    "ping": Spec(READ, {}, forward=False, doc="liveness of the command daemon"),
    "status": Spec(READ, {}, forward=False, doc="state, mission, active task, joints, timing, last log"),
    "describe": Spec(READ, {}, doc="robot, joints, tasks, the mission's signals and actions"),
    "params": Spec(READ, {"task": (str,)}, doc="tunable parameters: value, bounds, unit"),
    "events": Spec(
        READ,
        {"last": (int,), "follow": (bool,), "duration_s": NUMBER},
        forward=False,
        doc="the reactive trace: each instant's inputs and actions, time-stamped",
    ),
    "monitor": Spec(
        READ,
        {"signals": (list,), "rate_hz": NUMBER, "count": (int,), "duration_s": NUMBER},
        forward=False,
        doc="live signals, decimated to rate_hz",
    ),
    "load": Spec(CONTROL, {"path": (str,)}, ("path",), doc="compile, verify and prepare a mission"),
    "start": Spec(CONTROL, {"procedure": (str,)}, doc="run the loaded mission's main procedure"),
    "stop": Spec(CONTROL, {}, doc="graceful: the mission's Stop input"),
    "abort": Spec(CONTROL, {}, doc="immediate safe stop"),
    "hold": Spec(CONTROL, {}, doc="suspend the mission, hold position"),
    "resume": Spec(CONTROL, {}, doc="resume the suspended task from the measured state"),
    "reset": Spec(CONTROL, {}, doc="clear a safe stop once the arm is at rest"),
    "send": Spec(CONTROL, {"input": (str,)}, ("input",), doc="an operator input of the mission"),
    "tune": Spec(
        CONTROL, {"path": (str,), "value": (*NUMBER, list)}, ("path", "value"), doc="TASK.MODULE.PARAM"
    ),
    "inject": Spec(
        CONTROL, {"fault": (str,), "ticks": (int,), "extra_ms": NUMBER}, ("fault",), doc="test faults"
    ),
    "log": Spec(
        CONTROL,
        {"action": (str,), "signals": (list,), "path": (str,)},
        ("action",),
        forward=False,
        doc="start/stop a full-rate CSV log",
    ),
}


class ProtocolError(Exception):
    pass


def parse_request(line: bytes) -> tuple[Any, str, dict[str, Any]]:
    """(id, cmd, args) of a well-formed request; `ProtocolError` (with the id if known) otherwise."""
    try:
        msg = json.loads(line)
    except (ValueError, UnicodeDecodeError) as e:
        raise ProtocolError(f"not JSON: {e}") from None
    if not isinstance(msg, dict):
        raise ProtocolError('a request is a JSON object {"cmd": ..., "args": {...}}')
    unknown = set(msg) - {"id", "cmd", "args"}
    if unknown:
        raise ProtocolError(
            f"unknown request fields: {', '.join(sorted(map(str, unknown)))} (fields: id, cmd, args)"
        )
    cmd = msg.get("cmd")
    if not isinstance(cmd, str):
        raise ProtocolError("'cmd' must be a string")
    spec = COMMANDS.get(cmd)
    if spec is None:
        raise ProtocolError(f"unknown command {cmd!r} (commands: {', '.join(sorted(COMMANDS))})")
    args = msg.get("args", {})
    if not isinstance(args, dict):
        raise ProtocolError("'args' must be an object")
    for k, v in args.items():
        if k not in spec.args:
            allowed = ", ".join(spec.args) or "none"
            raise ProtocolError(f"{cmd}: unknown argument {k!r} (arguments: {allowed})")
        types = spec.args[k]
        if isinstance(v, bool) and bool not in types:
            raise ProtocolError(f"{cmd}: argument {k!r} must be {_types(types)}, not a boolean")
        if not isinstance(v, types):
            raise ProtocolError(f"{cmd}: argument {k!r} must be {_types(types)}, not {type(v).__name__}")
    for k in spec.required:
        if k not in args:
            raise ProtocolError(f"{cmd}: argument {k!r} is required")
    return msg.get("id"), cmd, args


def _types(types: tuple[type, ...]) -> str:
    names = {int: "a number", float: "a number", str: "a string", list: "a list", bool: "a boolean"}
    return " or ".join(dict.fromkeys(names.get(t, t.__name__) for t in types))


def encode(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, default=str) + "\n").encode()
