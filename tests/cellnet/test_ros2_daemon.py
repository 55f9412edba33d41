"""A daemon with `ros2 = true` as ROS 2 sees it through rmw_zenoh (no ROS here: a Zenoh peer reads
what an rmw_zenoh subscriber would, decoded by the test's own CDR reader, built from the spec)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from orccadd.cellnet.zconfig import to_json5, zenoh_config
from orccadd.config.cellnet import load_cellnet
from tests.cellnet.conftest import start_member
from tests.cellnet.test_ros2 import read_joint_state

zenoh = pytest.importorskip("zenoh")


def test_a_daemon_with_ros2_is_a_node_ros_can_echo(tmp_path: Path) -> None:
    """`ros2 = true` on a read-only cell (no TLS: anyone on the loopback may read): a peer
    subscribed as rmw_zenoh's would be sees the node's tokens and a JointState of the arm."""
    m = start_member(tmp_path, "test", "arm-a", None, [], extra="ros2 = true\n")
    try:
        raw = {"name": "test", "robot": "ros", "connect": [m.endpoint]}
        net = load_cellnet(raw, "<test>", "ros")
        s = zenoh.open(zenoh.Config.from_json5(to_json5(zenoh_config(net, daemon=False))))
        got: list[bytes] = []
        try:
            sub = s.declare_subscriber(
                "0/arm_a/joint_states/**", lambda sample: got.append(sample.payload.to_bytes())
            )
            deadline = time.monotonic() + 10
            while not got and time.monotonic() < deadline:
                time.sleep(0.05)
            tokens = [str(r.ok.key_expr) for r in s.liveliness().get("@ros2_lv/0/**", timeout=2.0) if r.ok]
            sub.undeclare()
        finally:
            s.close()
    finally:
        m.daemon.stop()
    assert got, "no JointState"
    js = read_joint_state(got[-1])
    assert js["name"][0] == "shoulder_pan_joint" and len(js["position"]) == 6, js  # type: ignore[index,arg-type]
    assert any("/NN/" in t and t.endswith("/%arm_a/orccadd") for t in tokens), tokens
    assert any(
        "/MP/" in t and "%arm_a%joint_states/sensor_msgs::msg::dds_::JointState_/" in t for t in tokens
    ), tokens
