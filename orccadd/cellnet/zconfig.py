"""A peer's Zenoh configuration from its `[cell]` table: mode peer, explicit endpoints, no
multicast scouting unless asked, TLS with mutual authentication, and, on a daemon, the access
control that gives each certificate its role.

The access control (Zenoh's, matching the peer certificate's common name) lets every listed peer
subscribe to what this daemon publishes, query its `read` key and declare its liveliness token
under its own name; the names in `control` alone put there (`orccadd/<cell>/<its name>/…`: their
signals; a peer cannot speak for another, and a read-only one feeds no mission) and reach the
`control` key. Everything else, and every peer not listed, is denied. With `ros2 = true` the
rules name rmw_zenoh's `@ros2_lv/**` too: Zenoh's `**` does not match a chunk beginning with `@`,
so the node's liveliness tokens would reach no peer (a read peer saw the JointStates, not the node).

A daemon takes no Zenoh message longer than `DAEMON_RX_MESSAGE_MAX` (reassembled from a link's
fragments): what it is sent is a request line (at most `MAX_LINE` bytes), a signal (at most 4 KiB)
or a declaration; a longer one is dropped by Zenoh before it is stored whole.

A console's access control (`console_access_control`) is the other side: it sends anything, and
takes in only what each daemon of its `daemons` says under its own name (replies, samples,
liveliness tokens, queryables), matched on that daemon's certificate. A reply to a request to
arm-b can then come from arm-b's certificate alone.
"""

from __future__ import annotations

import json
from typing import Any

from orccadd.cellnet import keys
from orccadd.config.cellnet import CellNetConfig
from orccadd.wire.commands import MAX_LINE

LOOPBACK_ANY_PORT = "127.0.0.1:0"
ROS2_ADMIN_SPACE = "@ros2_lv"  # rmw_zenoh's liveliness tokens (`cellnet.ros2.ADMIN_SPACE`: numpy-free here)
# Zenoh's `transport.link.rx.max_message_size` on a daemon (its default is 1 GiB: a peer's 200 MiB
# put was held whole in memory before any callback saw it). A request line with Zenoh's headers
# fits; a message beyond it is dropped on reassembly, the link kept (zenoh 1.10; not counted here).
DAEMON_RX_MESSAGE_MAX = 2 * MAX_LINE
LEASE_MS = 1000  # a link silent this long is closed: a peer cut off is lost within about a second
KEEP_ALIVES = 4  # per lease
EVERY_MESSAGE = [
    "put",
    "delete",
    "reply",
    "query",
    "liveliness_token",
    "liveliness_query",
    "declare_subscriber",
    "declare_liveliness_subscriber",
    "declare_queryable",
]


def zenoh_config(net: CellNetConfig, daemon: bool) -> dict[str, Any]:
    """The Zenoh config (a JSON5 table) of this peer; `daemon`: with the access control."""
    proto = "tls" if net.secured else "tcp"
    conf: dict[str, Any] = {
        "mode": "peer",
        "listen": {"endpoints": list(net.listen) or [f"{proto}/{LOOPBACK_ANY_PORT}"]},
        "connect": {"endpoints": list(net.connect)},
        # no multicast unless asked; a peer tells its neighbours the peers it knows (gossip,
        # over the links it has): a console connected to one daemon reaches every one
        "scouting": {"multicast": {"enabled": net.scouting}, "gossip": {"enabled": True, "multihop": True}},
    }
    conf["transport"] = {"link": {"tx": {"lease": LEASE_MS, "keep_alive": KEEP_ALIVES}}}
    if daemon:
        conf["transport"]["link"]["rx"] = {"max_message_size": DAEMON_RX_MESSAGE_MAX}
    if net.secured:
        ca, cert, key = (str(p) for p in net.tls_files())
        conf["transport"]["link"]["tls"] = {
            "root_ca_certificate": ca,
            "enable_mtls": True,
            "listen_certificate": cert,
            "listen_private_key": key,
            "connect_certificate": cert,
            "connect_private_key": key,
            # peers are named by their certificates' common names, not by host names
            "verify_name_on_connect": False,
        }
        if daemon:
            conf["access_control"] = access_control(net)
        elif net.daemons:
            conf["access_control"] = console_access_control(net)
    return conf


def to_json5(conf: dict[str, Any]) -> str:
    return json.dumps(conf)


def access_control(net: CellNetConfig) -> dict[str, Any]:
    """Zenoh's access control for a daemon: default deny; see the module's docstring."""
    cell, me = net.name, net.robot
    names = list(dict.fromkeys([*net.control, *net.read]))
    # `**` matches no chunk that begins with '@' (a verbatim chunk, zenoh 1.x): rmw_zenoh's
    # liveliness tokens under `@ros2_lv/…` are named on their own, or no peer would see them
    everywhere = ["**", f"{ROS2_ADMIN_SPACE}/**"] if net.ros2 else ["**"]
    rules: list[dict[str, Any]] = [
        _rule("to-peers", ["egress"], EVERY_MESSAGE, everywhere),
        _rule(
            "interest",
            ["ingress"],
            [
                "declare_subscriber",
                "declare_liveliness_subscriber",
                "liveliness_query",
                "declare_queryable",
                "reply",
            ],
            everywhere,
        ),
        _rule("read", ["ingress"], ["query"], [keys.robot_key(cell, me, keys.READ)]),
        _rule("control", ["ingress"], ["query"], [keys.robot_key(cell, me, keys.CONTROL)]),
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for n in names:
        own = f"own:{n}"
        # a read-only peer says nothing a mission takes: its liveliness token only (its loss is news)
        says = ["put", "delete", "liveliness_token"] if n in net.control else ["liveliness_token"]
        rules.append(_rule(own, ["ingress"], says, [keys.robot_key(cell, n, "**")]))
        subjects.append({"id": f"peer:{n}", "cert_common_names": [n]})
        granted = ["to-peers", "interest", own, "read"] + (["control"] if n in net.control else [])
        policies.append({"id": f"role:{n}", "rules": granted, "subjects": [f"peer:{n}"]})
    return _deny_by_default(rules, subjects, policies)


def console_access_control(net: CellNetConfig) -> dict[str, Any]:
    """A console's access control: default deny; everything it sends allowed; from each daemon D
    of `net.daemons` (its certificate), what D says under `orccadd/<cell>/D/` and the interest
    declarations a link needs; from every other certificate, nothing."""
    rules: list[dict[str, Any]] = [
        _rule("to-daemons", ["egress"], EVERY_MESSAGE, ["**"]),
        _rule(
            "interest",
            ["ingress"],
            ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            ["**"],
        ),
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for d in net.daemons:
        own = f"says:{d}"
        rules.append(
            _rule(
                own,
                ["ingress"],
                ["put", "delete", "reply", "liveliness_token", "declare_queryable"],
                [keys.robot_key(net.name, d, "**")],
            )
        )
        subjects.append({"id": f"daemon:{d}", "cert_common_names": [d]})
        policies.append({"id": f"trust:{d}", "rules": ["interest", own], "subjects": [f"daemon:{d}"]})
    policies.append({"id": "send", "rules": ["to-daemons"], "subjects": [s["id"] for s in subjects]})
    return _deny_by_default(rules, subjects, policies)


def _deny_by_default(
    rules: list[dict[str, Any]], subjects: list[dict[str, Any]], policies: list[dict[str, Any]]
) -> dict[str, Any]:
    """Zenoh's access control table: what the rules allow to their subjects, nothing else."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _rule(rid: str, flows: list[str], messages: list[str], key_exprs: list[str]) -> dict[str, Any]:
    return {"id": rid, "permission": "allow", "flows": flows, "messages": messages, "key_exprs": key_exprs}
