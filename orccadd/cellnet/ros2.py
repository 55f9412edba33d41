"""A daemon seen by ROS 2 as a node over rmw_zenoh, without ROS installed.

On a ROS 2 host with `RMW_IMPLEMENTATION=rmw_zenoh_cpp` on the same Zenoh network, `ros2 node list`
shows a `Ros2Node`, `ros2 topic echo /arm_a/joint_states` its sensor_msgs/msg/JointState and
`ros2 topic echo /rosout` its rcl_interfaces/msg/Log: we put the bytes on the key expressions, with
the liveliness tokens and attachments, that rmw_zenoh uses.

Pinned: rmw_zenoh_cpp 0.2.10, ROS 2 Jazzy (tag `release/jazzy/rmw_zenoh_cpp/0.2.10-1` of
github.com/ros2-gbp/rmw_zenoh-release, from github.com/ros2/rmw_zenoh, jazzy branch). Each format
was read in its src/detail/ (liveliness_utils.cpp, attachment_helpers.cpp, rmw_publisher_data.cpp,
rmw_node_data.cpp, qos.cpp, type_support_common.cpp, cdr.cpp) and is the same from 0.2.4 (where
the attachment lost its key strings, ros2/rmw_zenoh#601) to 0.2.10.

- Data key: `<domain>/<topic without its leading '/'>/<pkg>::msg::dds_::<Type>_/RIHS01_<hash>`.
- Tokens: `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/NN/<enclave>/<namespace>/<node name>`;
  a publisher's has its own entity id, `MP`, then `/<topic>/<dds type>/<type hash>/<qos>`. Each
  '/' inside a part is written '%' (so the enclave and root namespace '/' are '%'). A node's two
  ids are equal; a ROS context counts ids from 0. The zid is `str(session.info.zid())`.
- QoS: `<rel>:<dur>:<hist>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<s>,<ns>`, rmw
  enum numbers, a field left empty where it equals rmw_zenoh's default (RELIABLE, VOLATILE,
  KEEP_LAST, depth 42, infinite durations, AUTOMATIC liveliness).
- Attachment: zenoh-ext serialization of (int64 sequence number from 1, int64 source timestamp in
  ns since the epoch, std::array<uint8_t, 16> gid): two little-endian int64s, then the array as a
  sequence, LEB128 length 0x10 and 16 bytes; 33 bytes.
- Payload: CDR, 4-byte encapsulation header 00 01 00 00 (little endian), as Fast-CDR writes it:
  alignment counted from the end of the header, none before an empty array.
- Gid: XXH3-128 of the whole liveliness token, its low 64 bits then its high 64 bits, each in
  the machine's (little-endian) order (liveliness_utils.cpp, `Entity::Entity`): the gid
  `ros2 topic info -v` derives from our token is the one our samples carry.

Type hashes (RIHS01, REP 2011) come from rosbags' Jazzy typestore; tests/cellnet/test_ros2.py pins
them to values published elsewhere (a captured rmw_zenoh /rosout token, `ros2 topic info -v`).

Names: our robot names may hold '-', which no ROS name allows: `ros_name` turns each character
outside [A-Za-z0-9_] into '_' (`arm-a` -> `arm_a`, which then collides with `arm_a`) and puts '_'
before a leading digit. Events go to `/rosout`, named after the node's logger (`arm_a.orccadd`):
that is where rqt_console, `ros2 topic echo /rosout` and rosbag look, not a topic of our own.
"""

from __future__ import annotations

import re
import struct
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np
import xxhash
from numpy.typing import ArrayLike, NDArray
from rosbags.typesys import Stores, get_typestore

if TYPE_CHECKING:
    import zenoh

RMW_ZENOH_RELEASE = "release/jazzy/rmw_zenoh_cpp/0.2.10-1"
JOINT_STATE = "sensor_msgs/msg/JointState"
LOG = "rcl_interfaces/msg/Log"
ROSOUT = "/rosout"
ADMIN_SPACE = "@ros2_lv"
GID_SIZE = 16  # RMW_GID_STORAGE_SIZE since Iron

_STORE = get_typestore(Stores.ROS2_JAZZY)
_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_NAME = re.compile(_TOKEN)
_ABSOLUTE = re.compile(rf"/({_TOKEN}(/{_TOKEN})*)?")
_NOT_ROS = re.compile(r"[^A-Za-z0-9_]")


class LogLevel(IntEnum):
    """rcl_interfaces/msg/Log levels."""

    DEBUG = 10
    INFO = 20
    WARN = 30
    ERROR = 40
    FATAL = 50


@dataclass(frozen=True)
class Qos:
    """A publisher's QoS as its token states it: KEEP_LAST `depth` (or KEEP_ALL), RELIABLE (or
    BEST_EFFORT), VOLATILE (or TRANSIENT_LOCAL); durations in ns, None for infinite; liveliness
    AUTOMATIC with an infinite lease."""

    depth: int = 10
    best_effort: bool = False
    transient_local: bool = False
    keep_all: bool = False
    deadline_ns: int | None = None
    lifespan_ns: int | None = None

    def __post_init__(self) -> None:
        if self.depth < 1:
            raise ValueError(f"depth (={self.depth}) must be >= 1")
        if min(self.deadline_ns or 0, self.lifespan_ns or 0) < 0:
            raise ValueError(f"{self}: durations must be >= 0 or None (infinite)")


DEFAULT_QOS = Qos()  # rclcpp's `create_publisher(topic, 10)`
ROSOUT_QOS = Qos(depth=1000)  # rcl's rosout depth (its TRANSIENT_LOCAL and 10 s lifespan: not offered)


def ros_name(name: str) -> str:
    """`name` as one ROS name token (`arm-a` -> `arm_a`, `2f` -> `_2f`)."""
    token = _NOT_ROS.sub("_", name)
    if not token:
        raise ValueError("a ROS name cannot be empty")
    return "_" + token if token[0].isdigit() else token


def dds_type_name(type_name: str) -> str:
    """`sensor_msgs/msg/JointState` -> `sensor_msgs::msg::dds_::JointState_`."""
    parts = type_name.split("/")
    if len(parts) != 3 or not all(_NAME.fullmatch(p) for p in parts):
        raise ValueError(f"type name (={type_name!r}) must be <package>/<msg|srv>/<Type>")
    return f"{parts[0]}::{parts[1]}::dds_::{parts[2]}_"


@cache
def type_hash(type_name: str) -> str:
    """The RIHS01 hash of a type of rosbags' Jazzy typestore."""
    return str(_STORE.hash_rihs01(type_name))


def qos_string(qos: Qos) -> str:
    """The QoS part of a publisher's token (rmw_zenoh's `qos_to_keyexpr`)."""

    def duration(ns: int | None) -> str:  # infinite: {9223372036 s, 854775807 ns}, the default
        sec, nsec = divmod(ns, 1_000_000_000) if ns is not None else (9_223_372_036, 854_775_807)
        return f"{'' if sec == 9_223_372_036 else sec},{'' if nsec == 854_775_807 else nsec}"

    reliability = "2" if qos.best_effort else ""  # RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT
    durability = "1" if qos.transient_local else ""  # RMW_QOS_POLICY_DURABILITY_TRANSIENT_LOCAL
    history = "2" if qos.keep_all else ""  # RMW_QOS_POLICY_HISTORY_KEEP_ALL
    depth = "" if qos.depth == 42 else str(qos.depth)
    deadline, lifespan = duration(qos.deadline_ns), duration(qos.lifespan_ns)
    return f"{reliability}:{durability}:{history},{depth}:{deadline}:{lifespan}:,,"


def _check_absolute(what: str, name: str, allow_root: bool) -> None:
    if not _ABSOLUTE.fullmatch(name) or (name == "/" and not allow_root):
        raise ValueError(f"{what} (={name!r}) must be an absolute ROS name: /{_TOKEN}[/...]")


def _mangle(name: str) -> str:
    return name.replace("/", "%")


def topic_key(domain_id: int, topic: str, type_name: str) -> str:
    """The key expression of a topic's samples, e.g. for topic `/arm_a/joint_states`."""
    _check_absolute("topic", topic, allow_root=False)
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash(type_name)}"


def node_token(
    domain_id: int, zid_hex: str, node_id: int, namespace: str, node_name: str, enclave: str = "/"
) -> str:
    """A node's liveliness token; `namespace` and `enclave` are absolute (`/`, `/arm_a`)."""
    if not re.fullmatch(r"[0-9a-f]{1,32}", zid_hex):
        raise ValueError(f"zid (={zid_hex!r}) must be the session id in lowercase hex")
    _check_absolute("namespace", namespace, allow_root=True)
    _check_absolute("enclave", enclave, allow_root=True)
    if not _NAME.fullmatch(node_name):
        raise ValueError(f"node name (={node_name!r}) must match {_TOKEN}")
    ids = (str(domain_id), zid_hex, str(node_id), str(node_id))
    return "/".join((ADMIN_SPACE, *ids, "NN", _mangle(enclave), _mangle(namespace), node_name))


def publisher_token(
    domain_id: int,
    zid_hex: str,
    node_id: int,
    entity_id: int,
    namespace: str,
    node_name: str,
    topic: str,
    type_name: str,
    qos: Qos = DEFAULT_QOS,
    enclave: str = "/",
) -> str:
    """A publisher's liveliness token: its node's, with its own id and kind MP, then its topic,
    type, type hash and QoS."""
    parts = node_token(domain_id, zid_hex, node_id, namespace, node_name, enclave).split("/")
    parts[4:6] = (str(entity_id), "MP")
    type_and_hash = topic_key(domain_id, topic, type_name).split("/")[-2:]  # checks topic and type
    return "/".join((*parts, _mangle(topic), *type_and_hash, qos_string(qos)))


def gid_of(token: str) -> bytes:
    """A publisher's 16-byte gid, from its token as rmw_zenoh derives it (the module docstring)."""
    return int(xxhash.xxh3_128_intdigest(token.encode())).to_bytes(GID_SIZE, "little")


def attachment(sequence: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """The 33-byte attachment rmw_zenoh puts with each sample."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"gid has {len(gid)} bytes, must have {GID_SIZE}")
    try:
        return struct.pack("<qqB", sequence, source_timestamp_ns, GID_SIZE) + bytes(gid)
    except struct.error:
        raise ValueError(
            f"sequence (={sequence}) and source_timestamp_ns (={source_timestamp_ns}) must be int64s"
        ) from None


def _time(stamp_ns: int) -> Any:
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    if not -(2**31) <= sec < 2**31:
        raise ValueError(f"stamp_ns (={stamp_ns}) is out of builtin_interfaces/Time's int32 seconds")
    return _STORE.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _column(what: str, values: ArrayLike, n: int) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 1 or len(array) not in (0, n):
        raise ValueError(f"{what} has shape {array.shape}, must be ({n},) or (0,)")
    return array


def joint_state_cdr(
    stamp_ns: int,
    names: Sequence[str],
    position_rad: ArrayLike,
    velocity_rad_s: ArrayLike,
    effort_nm: ArrayLike,
    frame_id: str = "",
) -> bytes:
    """A sensor_msgs/msg/JointState payload; each array has one value per name, or none."""
    n = len(names)
    message = _STORE.types[JOINT_STATE](
        header=_STORE.types["std_msgs/msg/Header"](stamp=_time(stamp_ns), frame_id=frame_id),
        name=list(names),
        position=_column("position_rad", position_rad, n),
        velocity=_column("velocity_rad_s", velocity_rad_s, n),
        effort=_column("effort_nm", effort_nm, n),
    )
    return bytes(_STORE.serialize_cdr(message, JOINT_STATE, little_endian=True))


def log_cdr(
    stamp_ns: int, level: int, name: str, msg: str, file: str = "", function: str = "", line: int = 0
) -> bytes:
    """An rcl_interfaces/msg/Log payload; `level` is a `LogLevel`, `name` the logger's name."""
    if level not in set(LogLevel):
        raise ValueError(f"level (={level}) must be one of {[int(v) for v in LogLevel]}")
    if not 0 <= line < 2**32:
        raise ValueError(f"line (={line}) must be a uint32")
    stamp = _time(stamp_ns)
    message = _STORE.types[LOG](
        stamp=stamp, level=int(level), name=name, msg=msg, file=file, function=function, line=line
    )
    return bytes(_STORE.serialize_cdr(message, LOG, little_endian=True))


class _Publisher:
    """One ROS publisher: a Zenoh publisher, its liveliness token, gid and sequence numbers."""

    def __init__(self, session: zenoh.Session, token: str, key: str, qos: Qos) -> None:
        import zenoh

        if qos.transient_local or qos.keep_all:
            raise ValueError(f"{qos} is not offered: a Ros2Node keeps no cache and never blocks")
        options: dict[str, Any] = {"congestion_control": zenoh.CongestionControl.DROP}
        if qos.best_effort:
            options["reliability"] = zenoh.Reliability.BEST_EFFORT
        self.token, self.key, self.gid = token, key, gid_of(token)
        self._publisher = session.declare_publisher(key, **options)  # as rmw_zenoh: data, then token
        self._liveliness = session.liveliness().declare_token(token)
        self._sequence = 0
        self._lock = threading.Lock()

    def put(self, payload: bytes, clock_ns: Callable[[], int]) -> None:
        with self._lock:
            self._sequence += 1
            self._publisher.put(payload, attachment=attachment(self._sequence, clock_ns(), self.gid))

    def close(self) -> None:
        self._liveliness.undeclare()  # type: ignore[no-untyped-call]
        self._publisher.undeclare()  # type: ignore[no-untyped-call]


class Ros2Node:
    """One ROS 2 node on a Zenoh session: its token, a `<namespace>/joint_states` publisher and a
    `/rosout` publisher, each with its token, gid and sequence numbers from 1.

    `namespace` (chunks split at '/') and `node_name` go through `ros_name` (`cell/arm-a` ->
    `/cell/arm_a`). Entity ids `node_id`, +1 and +2 must be unique on the session: give each Ros2Node
    of a session its own `node_id` (0, 3, ...). `clock_ns` stamps the attachments (ns since the
    epoch). Publishing serializes with rosbags (tens of µs): call it from a publishing thread, not
    from a tick.
    """

    def __init__(
        self,
        session: zenoh.Session,
        namespace: str,
        node_name: str,
        domain_id: int = 0,
        *,
        node_id: int = 0,
        joint_state_qos: Qos = DEFAULT_QOS,
        log_qos: Qos = ROSOUT_QOS,
        clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        chunks = [ros_name(chunk) for chunk in namespace.split("/") if chunk]
        self.namespace, self.node_name = "/" + "/".join(chunks), ros_name(node_name)
        self.logger_name = ".".join([*chunks, self.node_name])
        self._clock_ns = clock_ns
        ids, ns = (domain_id, str(session.info.zid()), node_id), self.namespace
        self.node_token = node_token(*ids, ns, self.node_name)
        self._liveliness: zenoh.LivelinessToken | None = session.liveliness().declare_token(self.node_token)
        self._publishers: list[_Publisher] = []
        topics = ((f"{ns.rstrip('/')}/joint_states", JOINT_STATE, joint_state_qos), (ROSOUT, LOG, log_qos))
        try:
            for entity_id, (topic, type_name, qos) in enumerate(topics, start=node_id + 1):
                token = publisher_token(*ids, entity_id, ns, self.node_name, topic, type_name, qos)
                key = topic_key(domain_id, topic, type_name)
                self._publishers.append(_Publisher(session, token, key, qos))
        except BaseException:
            self.close()
            raise
        self._joint_states, self._rosout = self._publishers
        self.tokens = (self.node_token, *(p.token for p in self._publishers))
        self.joint_states_key, self.rosout_key = self._joint_states.key, self._rosout.key

    def publish_joint_state(
        self,
        stamp_ns: int,
        names: Sequence[str],
        position_rad: ArrayLike,
        velocity_rad_s: ArrayLike,
        effort_nm: ArrayLike,
        frame_id: str = "",
    ) -> None:
        """Put one JointState (stamp in ns since the epoch) on `<namespace>/joint_states`."""
        payload = joint_state_cdr(stamp_ns, names, position_rad, velocity_rad_s, effort_nm, frame_id)
        self._joint_states.put(payload, self._clock_ns)

    def publish_log(
        self, stamp_ns: int, level: int, msg: str, file: str = "", function: str = "", line: int = 0
    ) -> None:
        """Put one Log on `/rosout`, named after this node's logger."""
        payload = log_cdr(stamp_ns, level, self.logger_name, msg, file, function, line)
        self._rosout.put(payload, self._clock_ns)

    def close(self) -> None:
        """Undeclare the publishers and tokens: ROS sees the node leave. Idempotent."""
        publishers, self._publishers = self._publishers, []
        for publisher in publishers:
            publisher.close()
        liveliness, self._liveliness = self._liveliness, None
        if liveliness is not None:
            liveliness.undeclare()  # type: ignore[no-untyped-call]
