"""A daemon as a ROS 2 node over rmw_zenoh (jazzy 0.2.10): CDR checked by a decoder written here from
the CDR rules (not from the encoder), keys, tokens and attachments against literal values (tokens
captured from a running rmw_zenoh, the release's source), and a real Zenoh session pair on loopback."""

from __future__ import annotations

import json
import socket
import struct
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from orccadd.cellnet import ros2

zenoh = pytest.importorskip("zenoh")

JOINT_STATE_HASH = "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
LOG_HASH = "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
# A ROS 2 talker's session id, as captured with its tokens (see the token tests)
ZID = "ae35e834a80cb2398c738e251c05e716"


class Cdr:
    """Reads little-endian CDR: the 4-byte encapsulation header, then each primitive aligned to its
    size counted from the end of the header; strings are uint32 length (with the NUL), bytes, NUL."""

    def __init__(self, data: bytes) -> None:
        assert data[:4] == b"\x00\x01\x00\x00", data[:4].hex()  # CDR_LE, options 0
        self.body, self.pos = data[4:], 0

    def read(self, fmt: str) -> Any:
        size = struct.calcsize(fmt)
        self.pos += -self.pos % size
        (value,) = struct.unpack_from("<" + fmt, self.body, self.pos)
        self.pos += size
        return value

    def string(self) -> str:
        n = int(self.read("I"))
        raw = self.body[self.pos : self.pos + n]
        assert n >= 1 and raw[-1:] == b"\x00", raw
        self.pos += n
        return raw[:-1].decode()

    def strings(self) -> list[str]:
        return [self.string() for _ in range(int(self.read("I")))]

    def doubles(self) -> list[float]:
        n = int(self.read("I"))  # an empty sequence has no element to align
        return [float(self.read("d")) for _ in range(n)]

    def stamp_ns(self) -> int:
        sec, nanosec = self.read("i"), self.read("I")
        return int(sec) * 1_000_000_000 + int(nanosec)

    def done(self) -> None:
        assert self.pos == len(self.body), (self.pos, len(self.body))


def read_joint_state(data: bytes) -> dict[str, object]:
    r = Cdr(data)
    out = {"stamp_ns": r.stamp_ns(), "frame_id": r.string(), "name": r.strings()}
    out.update(position=r.doubles(), velocity=r.doubles(), effort=r.doubles())
    r.done()
    return out


def read_log(data: bytes) -> dict[str, object]:
    r = Cdr(data)
    out: dict[str, object] = {"stamp_ns": r.stamp_ns(), "level": r.read("B")}
    out.update(name=r.string(), msg=r.string(), file=r.string(), function=r.string(), line=r.read("I"))
    r.done()
    return out


def test_joint_state_round_trip() -> None:
    names = ["shoulder_pan", "elbow", "wrist_3"]
    data = ros2.joint_state_cdr(
        1_700_000_000_123_456_789, names, [0.5, -1.25, 3.0], [0.1, 0.2, 0.3], [], "base"
    )
    assert read_joint_state(data) == {
        "stamp_ns": 1_700_000_000_123_456_789,
        "frame_id": "base",
        "name": names,
        "position": [0.5, -1.25, 3.0],
        "velocity": [0.1, 0.2, 0.3],
        "effort": [],
    }


def test_joint_state_bytes_follow_cdr_to_the_byte() -> None:
    """Hand-written: padding to 4 before the name sequence and 8 before the doubles, none before the
    empty position (Fast-CDR aligns an array only when it has elements)."""
    data = ros2.joint_state_cdr(1_500_000_000, ["j1"], [], [], [1.0])
    expected = (
        "00010000"  # encapsulation: CDR little endian
        "01000000" "0065cd1d"  # stamp: sec 1, nanosec 500000000
        "01000000" "00" "000000"  # frame_id "": length 1, NUL, pad to 4
        "01000000" "03000000" "6a3100" "00"  # name: 1 string "j1" (length 3), pad to 4
        "00000000" "00000000"  # position, velocity: empty
        "01000000" "000000000000f03f"  # effort [1.0] at body offset 40, already 8-aligned
    )  # fmt: skip
    assert data.hex() == expected


def test_log_round_trip() -> None:
    data = ros2.log_cdr(42_000_000_007, ros2.LogLevel.WARN, "arm_a.orccadd", "overrun", "loop.py", "tick", 77)
    assert read_log(data) == {
        "stamp_ns": 42_000_000_007,
        "level": 30,
        "name": "arm_a.orccadd",
        "msg": "overrun",
        "file": "loop.py",
        "function": "tick",
        "line": 77,
    }


def test_payloads_refuse_what_ros_cannot_carry() -> None:
    with pytest.raises(ValueError, match=r"velocity_rad_s has shape \(1,\), must be \(2,\) or \(0,\)"):
        ros2.joint_state_cdr(0, ["a", "b"], [1.0, 2.0], [1.0], [])
    with pytest.raises(ValueError, match=r"level \(=15\)"):
        ros2.log_cdr(0, 15, "n", "m")
    with pytest.raises(ValueError, match=r"line \(=-1\)"):
        ros2.log_cdr(0, 20, "n", "m", line=-1)


def test_type_hashes_are_the_published_ones() -> None:
    """Values seen in a captured rmw_zenoh /rosout token, `ros2 topic info -v` output and rosbag2
    metadata (public files), and std_msgs/String in rmw_zenoh's own examples."""
    assert ros2.type_hash(ros2.JOINT_STATE) == JOINT_STATE_HASH
    assert ros2.type_hash(ros2.LOG) == LOG_HASH
    assert ros2.type_hash("std_msgs/msg/String") == STRING_HASH


def test_topic_key() -> None:
    key = ros2.topic_key(0, "/arm_a/joint_states", ros2.JOINT_STATE)
    assert key == f"0/arm_a/joint_states/sensor_msgs::msg::dds_::JointState_/{JOINT_STATE_HASH}"
    assert ros2.topic_key(7, "/rosout", ros2.LOG) == f"7/rosout/rcl_interfaces::msg::dds_::Log_/{LOG_HASH}"
    with pytest.raises(ValueError, match="absolute ROS name"):
        ros2.topic_key(0, "arm-a/joint_states", ros2.JOINT_STATE)


def test_publisher_tokens_match_tokens_captured_from_rmw_zenoh() -> None:
    """A demo talker's /rosout (rcl's QoS: TRANSIENT_LOCAL, depth 1000, lifespan 10 s) and /chatter
    (depth 7) tokens, as captured on a network of rmw_zenoh nodes."""
    rosout = ros2.Qos(depth=1000, transient_local=True, lifespan_ns=10_000_000_000)
    token = ros2.publisher_token(0, ZID, 0, 1, "/", "talker", "/rosout", ros2.LOG, rosout)
    assert token == (
        f"@ros2_lv/0/{ZID}/0/1/MP/%/%/talker/%rosout/rcl_interfaces::msg::dds_::Log_/{LOG_HASH}"
        "/:1:,1000:,:10,0:,,"
    )
    token = ros2.publisher_token(0, ZID, 0, 11, "/", "talker", "/chatter", "std_msgs/msg/String", ros2.Qos(7))
    assert token == (
        f"@ros2_lv/0/{ZID}/0/11/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
    )


def test_our_tokens() -> None:
    """liveliness_utils.cpp: node id twice for a node, '/' in a part written '%'."""
    assert ros2.node_token(0, ZID, 0, "/arm_a", "orccadd") == f"@ros2_lv/0/{ZID}/0/0/NN/%/%arm_a/orccadd"
    token = ros2.publisher_token(
        3, ZID, 0, 1, "/cell/arm_a", "orccadd", "/cell/arm_a/joint_states", ros2.JOINT_STATE
    )
    assert token == (
        f"@ros2_lv/3/{ZID}/0/1/MP/%/%cell%arm_a/orccadd/%cell%arm_a%joint_states/"
        f"sensor_msgs::msg::dds_::JointState_/{JOINT_STATE_HASH}/::,10:,:,:,,"
    )
    with pytest.raises(ValueError, match="node name"):
        ros2.node_token(0, ZID, 0, "/", "arm-a")


@pytest.mark.parametrize(
    ("qos", "text"),
    [
        (ros2.Qos(), "::,10:,:,:,,"),
        (ros2.Qos(depth=42), "::,:,:,:,,"),  # rmw_zenoh's default depth: empty
        (ros2.Qos(1, best_effort=True, keep_all=True), "2::2,1:,:,:,,"),
        (ros2.Qos(5, deadline_ns=1_500_000_000), "::,5:1,500000000:,:,,"),
    ],
)
def test_qos_string(qos: ros2.Qos, text: str) -> None:
    assert ros2.qos_string(qos) == text


def test_ros_names() -> None:
    assert ros2.ros_name("arm-a") == "arm_a"
    assert ros2.ros_name("2nd.arm") == "_2nd_arm"


def test_attachment_bytes() -> None:
    gid = bytes(range(16))
    data = ros2.attachment(5, 0x0102030405060708, gid)
    # int64 LE, int64 LE, the gid array as a sequence: LEB128 length, then its bytes
    assert data == bytes.fromhex("0500000000000000" "0807060504030201" "10") + gid  # fmt: skip
    # the same through zenoh's own serializer, the one rmw_zenoh's zenoh-cpp Serializer speaks
    expected = zenoh.ext.z_serialize((zenoh.ext.Int64(5), zenoh.ext.Int64(0x0102030405060708), gid))
    assert data == expected.to_bytes()
    with pytest.raises(ValueError, match="16"):
        ros2.attachment(1, 0, b"short")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def peer_config(listen: str, connect: list[str]) -> Any:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps([listen]))
    conf.insert_json5("connect/endpoints", json.dumps(connect))
    return conf


@pytest.fixture
def sessions() -> Iterator[tuple[Any, Any]]:
    """Two Zenoh peers on loopback, the second connected to the first."""
    opened = []
    try:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        opened.append(zenoh.open(peer_config(endpoint, [])))
        opened.append(zenoh.open(peer_config("tcp/127.0.0.1:0", [endpoint])))
        assert until(lambda: list(opened[1].info.peers_zid())), "the peers did not connect"
        yield opened[0], opened[1]
    finally:
        for s in opened:
            s.close()


def until(check: Callable[[], Any], timeout_s: float = 3.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while not (result := check()) and time.monotonic() < deadline:
        time.sleep(0.02)
    return result


def test_a_ros_peer_sees_the_node_its_joint_states_and_logs(sessions: tuple[Any, Any]) -> None:
    ours, theirs = sessions
    samples: list[Any] = []
    subscriber = theirs.declare_subscriber("0/**", samples.append)
    gone: list[str] = []
    watch = theirs.liveliness().declare_subscriber(
        "@ros2_lv/**", lambda s: gone.append(str(s.key_expr)) if s.kind == zenoh.SampleKind.DELETE else None
    )
    node = ros2.Ros2Node(ours, "arm-a", "orccadd", clock_ns=lambda: 1_234)
    try:
        zid = str(ours.info.zid())
        assert node.node_token == f"@ros2_lv/0/{zid}/0/0/NN/%/%arm_a/orccadd"
        assert node.tokens[1].startswith(f"@ros2_lv/0/{zid}/0/1/MP/%/%arm_a/orccadd/%arm_a%joint_states/")
        assert node.tokens[2].startswith(f"@ros2_lv/0/{zid}/0/2/MP/%/%arm_a/orccadd/%rosout/")

        def seen() -> set[str]:
            replies = theirs.liveliness().get("@ros2_lv/**", timeout=1.0)
            found = {str(r.ok.key_expr) for r in replies if r.ok is not None}
            return found if set(node.tokens) <= found else set()

        assert until(seen), "the node's and publishers' tokens were not seen"

        def joint_samples() -> list[Any]:  # until the subscription has reached our publisher
            node.publish_joint_state(5_000_000_001, ["j1", "j2"], [0.5, -0.5], [0.0, 1.0], [2.0, 3.0])
            return [s for s in samples if str(s.key_expr) == node.joint_states_key]

        got = until(joint_samples)
        assert got, "no JointState arrived"
        first = got[0]
        assert read_joint_state(first.payload.to_bytes()) == {
            "stamp_ns": 5_000_000_001,
            "frame_id": "",
            "name": ["j1", "j2"],
            "position": [0.5, -0.5],
            "velocity": [0.0, 1.0],
            "effort": [2.0, 3.0],
        }
        sequence, stamp, gid_len = struct.unpack_from("<qqB", first.attachment.to_bytes())
        assert (stamp, gid_len) == (1_234, 16)
        assert first.attachment.to_bytes()[17:] == ros2.gid_of(node.tokens[1])
        joint = [s for s in samples if str(s.key_expr) == node.joint_states_key]
        sequences = [struct.unpack_from("<q", s.attachment.to_bytes())[0] for s in joint]
        assert sequences == list(range(sequence, sequence + len(sequences)))  # one publisher, no gap

        node.publish_log(6_000_000_000, ros2.LogLevel.ERROR, "fault: overrun", line=3)
        logs = until(lambda: [s for s in samples if str(s.key_expr) == node.rosout_key])
        assert logs, "no Log arrived"
        log = logs[0]
        assert read_log(log.payload.to_bytes())["name"] == "arm_a.orccadd"
        assert struct.unpack_from("<q", log.attachment.to_bytes())[0] == 1  # its own sequence
    finally:
        node.close()
    assert until(lambda: set(node.tokens) <= set(gone)), "closing did not withdraw the tokens"
    subscriber.undeclare()
    watch.undeclare()


def test_a_node_refuses_a_qos_it_cannot_keep(sessions: tuple[Any, Any]) -> None:
    """rcl's own /rosout QoS is TRANSIENT_LOCAL: that needs a cache of samples, which we do not keep."""
    with pytest.raises(ValueError, match="not offered"):
        ros2.Ros2Node(sessions[0], "arm-a", "orccadd", log_qos=ros2.Qos(1000, transient_local=True))


def test_a_gid_is_the_xxh3_128_of_the_token_low_half_first() -> None:
    # XXH3-128 of no bytes is 99aa06d3014798d8 (high) 6001c324468d497f (low), xxHash's own test
    # vector; rmw_zenoh copies the low then the high 64 bits, each little-endian, into the gid
    assert ros2.gid_of("") == bytes.fromhex("7f498d4624c30160" "d8984701d306aa99")  # fmt: skip
