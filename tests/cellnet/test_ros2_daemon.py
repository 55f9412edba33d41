"""A daemon with `ros2 = true` as ROS 2 sees it through rmw_zenoh (no ROS here: a Zenoh peer reads
what an rmw_zenoh subscriber would, decoded by the test's own CDR reader, built from the spec):
on a read-only cell (no TLS), and on a TLS cell from a peer holding the read role only."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from orccadd.cellnet.ros2 import ADMIN_SPACE
from orccadd.cellnet.zconfig import ROS2_ADMIN_SPACE, to_json5, zenoh_config
from orccadd.config.cellnet import load_cellnet
from tests.cellnet.conftest import start_member
from tests.cellnet.test_hostile_peers import peer_session
from tests.cellnet.test_ros2 import read_joint_state

zenoh = pytest.importorskip("zenoh")


def what_ros_sees(s: Any, wait_s: float = 10.0) -> tuple[list[bytes], list[str]]:
    """(JointState payloads, ROS 2 liveliness tokens) `s` reaches: the first JointState waited
    for, then the tokens asked for as rmw_zenoh's graph cache asks (a liveliness query)."""
    got: list[bytes] = []
    sub = s.declare_subscriber(
        "0/arm_a/joint_states/**", lambda sample: got.append(sample.payload.to_bytes())
    )
    deadline = time.monotonic() + wait_s
    while not got and time.monotonic() < deadline:
        time.sleep(0.05)
    tokens: list[str] = []
    while time.monotonic() < deadline:  # the tokens may come a little after the first sample
        tokens = [str(r.ok.key_expr) for r in s.liveliness().get("@ros2_lv/0/**", timeout=2.0) if r.ok]
        if len(tokens) >= 3:
            break
        time.sleep(0.1)
    sub.undeclare()
    return got, tokens


def seen_as_a_node(got: list[bytes], tokens: list[str]) -> None:
    assert got, "no JointState"
    js = read_joint_state(got[-1])
    assert js["name"][0] == "shoulder_pan_joint" and len(js["position"]) == 6, js  # type: ignore[index,arg-type]
    assert any("/NN/" in t and t.endswith("/%arm_a/orccadd") for t in tokens), tokens
    assert any(
        "/MP/" in t and "%arm_a%joint_states/sensor_msgs::msg::dds_::JointState_/" in t for t in tokens
    ), tokens
    assert any("/MP/" in t and "%rosout/rcl_interfaces::msg::dds_::Log_/" in t for t in tokens), tokens


def test_a_daemon_with_ros2_is_a_node_ros_can_echo(tmp_path: Path) -> None:
    """`ros2 = true` on a read-only cell (no TLS: anyone on the loopback may read): a peer
    subscribed as rmw_zenoh's would be sees the node's tokens and a JointState of the arm."""
    m = start_member(tmp_path, "test", "arm-a", None, [], extra="ros2 = true\n")
    try:
        raw = {"name": "test", "robot": "ros", "connect": [m.endpoint]}
        net = load_cellnet(raw, "<test>", "ros")
        s = zenoh.open(zenoh.Config.from_json5(to_json5(zenoh_config(net, daemon=False))))
        try:
            got, tokens = what_ros_sees(s)
        finally:
            s.close()
    finally:
        m.daemon.stop()
    seen_as_a_node(got, tokens)


def test_a_read_peer_sees_the_ros2_node_under_tls(tmp_path: Path, certs: Path) -> None:
    """With TLS and the access control on, a peer of the read role (a ROS 2 host's certificate
    listed in `read`) sees the node's liveliness tokens, under `@ros2_lv/…`, which Zenoh's `**`
    does not match, and its topics; a peer of no role sees none of them."""
    assert ROS2_ADMIN_SPACE == ADMIN_SPACE  # the access control names rmw_zenoh's own
    m = start_member(
        tmp_path, "test", "arm-a", certs, [], control=("console",), read=("viewer",), extra="ros2 = true\n"
    )
    try:
        viewer = peer_session(certs, "viewer", m.endpoint)
        try:
            got, tokens = what_ros_sees(viewer)
        finally:
            viewer.close()
        stranger = peer_session(certs, "stranger", m.endpoint)
        try:
            not_got, not_tokens = what_ros_sees(stranger, wait_s=3.0)
        finally:
            stranger.close()
    finally:
        m.daemon.stop()
    seen_as_a_node(got, tokens)
    assert not not_got and not not_tokens, (len(not_got), not_tokens)
