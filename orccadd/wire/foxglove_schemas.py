"""The JSON schemas of the Foxglove channels (a log's MCAP, `orccadctl foxglove`'s live view), and
the helpers that fill their messages.

Each signal group of the log's selection (`q`, `dq`, `tau`, `cmd`, `wake_us`, ...) is one channel
`/<group>` whose messages carry `time_s` and one number per selected joint (or `value` for a
scalar); its unit is in the schema (`"unit"` of each property, and the schema's description) and
in the channel's metadata. `cmd`'s unit depends on the command mode, so its messages also carry
`mode` and `unit`. Foxglove's own schemas (`foxglove.Log`, `foxglove.JointStates`) are written
out here as JSON schemas under the names Foxglove recognises for JSON channels.
"""

from __future__ import annotations

import json
from typing import Any

from orccadd.fault import FaultKind

CMD_UNIT = "by mode: rad (position), rad/s (velocity), N.m (torque)"

NAMED = ("task", "phase", "mode")  # scalars whose messages also carry the name of their value


def _num(unit: str, description: str = "") -> dict[str, Any]:
    return {"type": ["number", "null"], "unit": unit, "description": f"{description} [{unit}]".strip()}


def group_schema(group: str, fields: list[str], unit: str) -> bytes:
    """The schema of one signal group's channel."""
    props: dict[str, Any] = {"time_s": _num("s", "seconds since the log started")}
    for f in fields:
        props[f] = _num(unit, f"{group}.{f}" if f != "value" else group)
    if group == "cmd":
        props["mode"] = {"type": "string", "enum": ["position", "velocity", "torque"]}
        props["unit"] = {"type": "string", "description": "the unit of this message's values"}
    if group in NAMED:
        props["name"] = {"type": "string"}
    if group == "status":
        props["flags"] = {"type": "array", "items": {"type": "string"}}
    schema = {
        "title": f"orccadd.{group}",
        "description": f"{group} [{unit if group != 'cmd' else CMD_UNIT}]",
        "type": "object",
        "properties": props,
    }
    return json.dumps(schema).encode()


_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}},
}

LOG_SCHEMA = json.dumps(
    {
        "title": "foxglove.Log",
        "description": "A log message",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "level": {"type": "integer", "enum": [0, 1, 2, 3, 4, 5], "description": "0 unknown .. 5 fatal"},
            "message": {"type": "string"},
            "name": {"type": "string"},
            "file": {"type": "string"},
            "line": {"type": "integer", "minimum": 0},
        },
    }
).encode()

# orccadd's own: why the arm was safe-stopped (`orccadd.fault.StopCause.to_wire`), typed
STOP_CAUSE_SCHEMA = json.dumps(
    {
        "title": "orccadd.StopCause",
        "description": "Why the arm was safe-stopped: the type 3 event raised and the fault behind it",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "n": {"type": "integer", "description": "the daemon's safe stops so far, this one's number"},
            "event": {
                "type": "string",
                "description": "the type 3 event (Move.T3.CommLost); empty for an abort",
            },
            "kind": {"type": "string", "enum": [k.value for k in FaultKind]},
            "resource": {"type": "string"},
            "joint": {"type": "string", "description": "empty when about the whole resource"},
            "code": {"type": "integer", "description": "the device's own code (0: none)"},
            "text": {"type": "string"},
        },
        "required": ["timestamp", "n", "event", "kind", "resource", "joint", "code", "text"],
    }
).encode()

JOINT_STATES_SCHEMA = json.dumps(
    {
        "title": "foxglove.JointStates",
        "description": "The state of a set of joints at a given time",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "joints": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "name": {"type": "string"},
                        "position": _num("rad"),
                        "velocity": _num("rad/s"),
                        "effort": _num("N.m"),
                    },
                },
            },
        },
    }
).encode()

STRING_SCHEMA = json.dumps(
    {"title": "std_msgs/msg/String", "type": "object", "properties": {"data": {"type": "string"}}}
).encode()

DEBUG, INFO, WARNING, ERROR = 1, 2, 3, 4


def level(kind: str, name: str, exception: int) -> int:
    """The foxglove.Log level of a log event: type 3 exceptions and safe stops are errors, type
    2 and the operator's stops warnings, mode changes debug, the rest info."""
    if kind == "mode":
        return DEBUG
    if exception == 3:
        return ERROR
    if kind == "gap" or exception == 2:
        return WARNING
    if kind == "command" and name in ("abort", "stop", "inject", "shutdown"):
        return WARNING
    return INFO


def stamp(wall_ns: int) -> dict[str, int]:
    return {"sec": wall_ns // 1_000_000_000, "nsec": wall_ns % 1_000_000_000}


def joint_state_name(resource: str, joint: str, every_joint: list[str]) -> str:
    """A joint's name on `/joint_states`: its own, or `resource/joint` when two resources of a
    station share it (two identical arms), as ROS prefixes do."""
    return f"{resource}/{joint}" if resource and every_joint.count(joint) > 1 else joint
