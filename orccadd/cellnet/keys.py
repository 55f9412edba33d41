"""The key expressions of a cell: everything one daemon says or answers is under
`orccadd/<cell>/<robot>/`.

    alive              its liveliness token (gone: the daemon is lost, within Zenoh's lease)
    status             JSON, `orccadctl status`'s result, at `status_hz` and on each event
    joints             JSON {t_s, resources: [{name, joints, q, dq, tau}]}, at `joints_hz`
    events             JSON, one trace event each (as `orccadctl events` prints them)
    signal/<NAME>      JSON {seq, wall_s, mission}: the mission emitted output NAME to the cell
                       (taken only from a peer with the control role, at most 4 KiB)
    read               queryable: a read-role request line (the socket's protocol)
    control            queryable: any request line (only peers with the control role reach it)
"""

from __future__ import annotations

ROOT = "orccadd"
ALIVE = "alive"
STATUS = "status"
JOINTS = "joints"
EVENTS = "events"
SIGNAL = "signal"
READ = "read"
CONTROL = "control"


def robot_key(cell: str, robot: str, *chunks: str) -> str:
    return "/".join((ROOT, cell, robot, *chunks))


def every_robot(cell: str, *chunks: str) -> str:
    """One chunk for each robot of the cell (`*`)."""
    return robot_key(cell, "*", *chunks)


def robot_of(cell: str, key: str) -> str:
    """The robot a key of the cell belongs to; ValueError if it is not one."""
    parts = str(key).split("/")
    if len(parts) < 4 or parts[0] != ROOT or parts[1] != cell:
        raise ValueError(f"{key!r} is not a key of cell {cell!r}")
    return parts[2]
