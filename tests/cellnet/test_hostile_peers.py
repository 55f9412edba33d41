"""What a peer of the cell sends a daemon cannot take it down: a malformed payload on every key
the daemon subscribes to or answers on is dropped (or answered with an error) and logged, and
the daemon carries on; a peer cannot speak under another's name."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.cellnet.zconfig import to_json5, zenoh_config
from orccadd.config.cellnet import load_cellnet
from tests.cellnet.conftest import Member, connected, start_member, until_matched

zenoh = pytest.importorskip("zenoh")

GARBAGE = [b"", b"\xff\xfe\x00", b"{", b"[1, 2]", b'{"seq": "one"}', b'{"seq": -3}', b'{"seq": true}',
           b"[" * 5000, b"x" * 100_000, b'{"seq": 1e400}']  # fmt: skip


@pytest.fixture
def arm_a(tmp_path: Path, certs: Path) -> Iterator[Member]:
    m = start_member(tmp_path, "test", "arm-a", certs, [], control=("console",))
    try:
        yield m
    finally:
        m.daemon.stop()


def peer_session(certs: Path, name: str, endpoint: str) -> zenoh.Session:
    raw = {"name": "test", "robot": name, "connect": [endpoint], "ca": str(certs / "ca.pem"),
           "certificate": str(certs / f"{name}.pem"), "private_key": str(certs / f"{name}.key")}  # fmt: skip
    net = load_cellnet(raw, "<test>", name)
    return connected(zenoh.open(zenoh.Config.from_json5(to_json5(zenoh_config(net, daemon=False)))))


PART_FROM_CONSOLE = """
mission TakesPart

resource arm
input Stop
input PartPlaced from "console"

main procedure Main
  handle
    do
      await PartPlaced
    until Stop
  on lost "console" do
    safe
  end
end

safe procedure Rest
  nothing
end
"""


def test_malformed_payloads_are_dropped_with_a_log_line(arm_a: Member, certs: Path) -> None:
    mission = arm_a.dir / "takes_part.mission"  # a signal is decoded only if a mission takes it
    mission.write_text(PART_FROM_CONSOLE)
    arm_a.daemon.call("load", path=str(mission))
    s = peer_session(certs, "console", arm_a.endpoint)
    try:
        until_matched(s, "orccadd/test/console/signal/PartPlaced")
        block = zenoh.CongestionControl.BLOCK  # each delivered: a put is dropped under congestion by default
        for raw in GARBAGE:
            s.put("orccadd/test/console/signal/PartPlaced", raw, congestion_control=block)
        replies = []
        for key in ("orccadd/test/arm-a/read", "orccadd/test/arm-a/control"):
            for raw in GARBAGE:
                for r in s.get(key, payload=raw, timeout=5.0):
                    replies.append(json.loads(r.ok.payload.to_bytes()))
    finally:
        s.close()
    assert len(replies) == 2 * len(GARBAGE)
    assert all(r["ok"] is False and r["error"] for r in replies), replies
    line = "a malformed signal on orccadd/test/console/signal/PartPlaced dropped"
    deadline = time.monotonic() + 10  # the puts are taken on Zenoh's thread, in their time
    while arm_a.daemon.log_text().count(line) < len(GARBAGE) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert arm_a.daemon.log_text().count(line) == len(GARBAGE)
    assert arm_a.daemon.call("ping")["pong"]
    assert arm_a.daemon.status()["state"] == "ready"  # the mission loaded, nothing started


def test_a_peer_cannot_speak_under_another_name(arm_a: Member, certs: Path) -> None:
    mission = arm_a.dir / "takes_part.mission"
    mission.write_text(PART_FROM_CONSOLE)
    arm_a.daemon.call("load", path=str(mission))
    s = peer_session(certs, "console", arm_a.endpoint)
    try:
        until_matched(s, "orccadd/test/console/signal/PartPlaced")  # arm-a hears the console now
        s.put("orccadd/test/arm-b/signal/PartPlaced", b"{")  # denied by arm-a's access control
        s.put("orccadd/test/console/signal/PartPlaced", b"{")  # the console's own: taken (and dropped)
        line = "a malformed signal on orccadd/test/console/signal/PartPlaced dropped"
        deadline = time.monotonic() + 10  # on the same link after the other: in the log after it
        while line not in arm_a.daemon.log_text():
            assert time.monotonic() < deadline, arm_a.daemon.log_text()[-2000:]
            time.sleep(0.05)
    finally:
        s.close()
    assert "arm-b/signal" not in arm_a.daemon.log_text()
