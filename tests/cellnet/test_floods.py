"""What a peer sends cannot swamp a daemon (issue 40): a control peer flooding signals is cut to
its rate, the drops counted and said in few lines, the mission's own outputs all published or
the shortfall counted; a read-only peer's signal feeds no mission; a read peer flooding the
`read` key leaves the console's `hold` and `resume` served; a payload beyond the bounds is
dropped (Zenoh's, or the daemon's), memory kept; a huge sequence number blocks nothing."""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from orccadd.cellnet.console import CellConsole, read_console_config
from orccadd.cellnet.zconfig import DAEMON_RX_MESSAGE_MAX
from orccadd.cmdd.cellguard import SIGNAL_MAX
from tests.cellnet.conftest import Member, console_file, start_member, until_matched
from tests.cellnet.test_hostile_peers import peer_session

zenoh = pytest.importorskip("zenoh")
BLOCK = zenoh.CongestionControl.BLOCK

ECHO = """
mission Echo

resource arm
input Stop
input Ping from "console"
output Pong to cell

main procedure Main
  handle
    do
      loop
        await Ping;
        emit Pong
      end
    until Stop
  on lost "console" do
    safe
  end
end

safe procedure Rest
  nothing
end
"""

FROM_VIEWER = """
mission FromViewer

resource arm
input Stop
input Ping from "viewer"

main procedure Main
  handle
    do
      loop
        await Ping
      end
    until Stop
  on lost "viewer" do
    safe
  end
end

safe procedure Rest
  nothing
end
"""

WAIT = """
mission Wait

resource arm
input Stop
input Go

main procedure Main
  do
    await Go
  until Stop
end

safe procedure Rest
  nothing
end
"""


@pytest.fixture
def arm_a(tmp_path: Path, certs: Path) -> Iterator[Member]:
    m = start_member(tmp_path, "test", "arm-a", certs, [], control=("console",), read=("viewer",))
    try:
        yield m
    finally:
        m.daemon.stop()


@pytest.fixture
def console(certs: Path, arm_a: Member) -> Iterator[Any]:
    """The console as a peer of the cell, its liveliness token there (a mission sees it)."""
    s = peer_session(certs, "console", arm_a.endpoint)
    token = s.liveliness().declare_token("orccadd/test/console/alive")
    try:
        yield s
    finally:
        token.undeclare()
        s.close()


def run(m: Member, name: str, text: str) -> None:
    path = m.dir / f"{name}.mission"
    path.write_text(text)
    m.daemon.call("load", path=str(path))
    m.daemon.call("start")
    assert m.daemon.status()["state"] == "running"


def counts(m: Member) -> dict[str, Any]:
    return dict(m.daemon.status()["cell"])


def wait_cell(m: Member, pred: Callable[[dict[str, Any]], bool], timeout_s: float = 60.0) -> dict[str, Any]:
    """The first status whose `cell` section satisfies `pred`."""
    return m.daemon.wait(lambda st: pred(st["cell"]), timeout_s)["cell"]  # type: ignore[no-any-return]


def signals(cell: dict[str, Any], peer: str, what: str) -> int:
    return int(cell["signals"].get(peer, {}).get(what, 0))


def put_all(session: Any, key: str, payloads: list[bytes]) -> None:
    """Every payload, in order, none dropped at the sender (a reliable, blocking publisher)."""
    pub = session.declare_publisher(key, congestion_control=BLOCK)
    for p in payloads:
        pub.put(p)
    pub.undeclare()


def ping(n: int) -> bytes:
    return json.dumps({"seq": n, "wall_s": time.time(), "mission": "Flood"}).encode()


def test_a_signal_flood_is_cut_to_the_rate_and_every_output_accounted_for(
    arm_a: Member, console: Any
) -> None:
    run(arm_a, "echo", ECHO)
    pongs: list[int] = []
    sub = console.declare_subscriber("orccadd/test/arm-a/signal/Pong", lambda s: pongs.append(1))
    flood = 10_000  # about 10,000/s, fifty times the rate: the burst, then 200/s taken
    pub = console.declare_publisher("orccadd/test/console/signal/Ping", congestion_control=BLOCK)
    for n in range(1, flood + 1):
        pub.put(ping(n))
        if n % 500 == 0:
            time.sleep(0.05)
    cell = wait_cell(
        arm_a, lambda c: signals(c, "console", "taken") + signals(c, "console", "over_rate") == flood
    )
    taken, dropped = signals(cell, "console", "taken"), signals(cell, "console", "over_rate")
    assert dropped >= flood // 2 and taken >= 50, cell
    out = wait_cell(arm_a, lambda c: accounted(c, taken))["outputs"]
    if out["lost"]:  # the real-time process's word of them lost on its link: said
        assert "NOT published" in arm_a.daemon.log_text()
    deadline = time.monotonic() + 30
    while len(pongs) < out["published"] and time.monotonic() < deadline:
        time.sleep(0.1)
    sub.undeclare()
    assert len(pongs) == out["published"]
    st = arm_a.daemon.status()
    assert st["state"] == "running" and not st["faulted"]  # the mission goes on, waiting for Pings
    said = [line for line in arm_a.daemon.log_text().splitlines() if "cell:" in line]
    assert len(said) < 100, said[:20]  # for thousands of drops
    assert any("over its rate" in line for line in said)


def accounted(cell: dict[str, Any], taken: int) -> bool:
    """Every output of the `taken` signals' instants published or counted lost (unless the trace
    overran, which the count says too)."""
    out = cell["outputs"]
    return bool(out["published"] + out["lost"] == taken or out["unchecked_trace_records"])


def test_a_read_only_peers_signal_feeds_no_mission(arm_a: Member, certs: Path) -> None:
    viewer = peer_session(certs, "viewer", arm_a.endpoint)
    token = viewer.liveliness().declare_token("orccadd/test/viewer/alive")  # a read peer's token: allowed
    try:
        run(arm_a, "from_viewer", FROM_VIEWER)
        until_matched(viewer, "orccadd/test/viewer/signal/Ping")  # else the puts would go nowhere
        for n in range(1, 6):
            viewer.put("orccadd/test/viewer/signal/Ping", ping(n))
        # a request after the puts, on the same link: answered once they have been dealt with
        line = json.dumps({"id": 1, "cmd": "status", "args": {}, "protocol": 1})
        replies = list(viewer.get("orccadd/test/arm-a/read", payload=line, timeout=10.0))
        assert replies and replies[0].ok is not None
        events = arm_a.daemon.call("events", last=50)["events"]
        assert not [e for e in events if "Ping" in e.get("inputs", [])], events
        st = arm_a.daemon.status()
        assert st["state"] == "running", st  # still waiting for a Ping it may not take from a viewer
        assert signals(st["cell"], "viewer", "taken") == 0
    finally:
        token.undeclare()
        viewer.close()


def test_a_read_flood_leaves_hold_and_resume_served(tmp_path: Path, certs: Path, arm_a: Member) -> None:
    run(arm_a, "wait", WAIT)
    viewer = peer_session(certs, "viewer", arm_a.endpoint)
    stop = threading.Event()
    line = json.dumps({"id": 1, "cmd": "describe", "args": {}, "protocol": 1})

    def flood() -> None:
        asked: list[Any] = []
        while not stop.is_set():
            asked.append(viewer.get("orccadd/test/arm-a/read", payload=line, timeout=30.0))
            if len(asked) > 5000:
                asked.clear()

    flooding = threading.Thread(target=flood)
    flooding.start()
    try:
        wait_cell(arm_a, lambda c: c["requests"]["read"]["busy"] > 0)  # beyond the bound: refused at once
        path = console_file(tmp_path, "test", "console", certs, [arm_a.endpoint], daemons=("arm-a",))
        with CellConsole(read_console_config(str(path))) as con:
            for cmd, state in (("hold", "holding"), ("resume", "running")):
                reply = con.request("arm-a", cmd)  # within the client's normal wait
                assert reply["ok"], reply
                assert arm_a.daemon.status()["state"] == state
    finally:
        stop.set()
        flooding.join()
        viewer.close()
    cell = wait_cell(arm_a, lambda c: c["requests"]["read"]["in_flight"] == 0)
    assert cell["requests"]["read"]["max"] == 16 and cell["requests"]["control"]["busy"] == 0


def cmdd_rss_mib(m: Member) -> float:
    """The resident memory of `m`'s command daemon (the process serving its socket)."""
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            if b"orccadd.cmdd" in argv and m.daemon.socket.encode() in argv:
                rss_kib = Path(f"/proc/{pid}/status").read_text().split("VmRSS:")[1].split()[0]
                return int(rss_kib) / 1024
        except (OSError, IndexError):
            continue
    raise AssertionError("no command daemon found")


def test_payloads_beyond_the_bounds_are_dropped_and_memory_kept(arm_a: Member, console: Any) -> None:
    run(arm_a, "echo", ECHO)
    before_mib = cmdd_rss_mib(arm_a)
    key = "orccadd/test/console/signal/Ping"
    put_all(console, key, [b"x" * (256 << 20)])  # beyond Zenoh's bound: dropped on reassembly
    put_all(console, key, [b" " * (DAEMON_RX_MESSAGE_MAX // 2) + ping(1)])  # beyond SIGNAL_MAX
    put_all(console, key, [ping(2)])  # the link still there: taken
    cell = wait_cell(arm_a, lambda c: signals(c, "console", "taken") == 1)
    assert signals(cell, "console", "malformed") == 1
    assert f"more than {SIGNAL_MAX}" in arm_a.daemon.log_text()
    assert cmdd_rss_mib(arm_a) - before_mib < 64  # not the 256 MiB payload, nor a copy of it


def test_a_huge_sequence_number_blocks_no_later_signal(arm_a: Member, console: Any) -> None:
    run(arm_a, "echo", ECHO)
    put_all(console, "orccadd/test/console/signal/Ping", [ping(n) for n in (10**15, 1, 2, 3)])
    cell = wait_cell(arm_a, lambda c: c["outputs"]["published"] == 4)
    assert signals(cell, "console", "taken") == 4 and signals(cell, "console", "restarts") == 1
    assert "counts again" in arm_a.daemon.log_text()


def test_undeclared_signal_names_are_counted_not_stored(arm_a: Member, console: Any) -> None:
    run(arm_a, "echo", ECHO)
    before_mib = cmdd_rss_mib(arm_a)
    for n in range(20_000):
        console.put(f"orccadd/test/console/signal/N{n}", ping(1))
    put_all(console, "orccadd/test/console/signal/Ping", [ping(1)])  # after them on the link
    cell = wait_cell(arm_a, lambda c: signals(c, "console", "taken") == 1)
    assert 0 < signals(cell, "console", "undeclared") <= 20_000  # the sender may drop some
    assert set(cell["signals"]) == {"console"}
    assert cmdd_rss_mib(arm_a) - before_mib < 32


def test_a_daemon_stopping_under_a_flood_says_nothing_more(arm_a: Member, console: Any) -> None:
    run(arm_a, "echo", ECHO)
    stop = threading.Event()

    def flood() -> None:
        n = 0
        while not stop.is_set():
            n += 1
            console.put("orccadd/test/console/signal/Ping", ping(n))

    flooding = threading.Thread(target=flood)
    flooding.start()
    try:
        wait_cell(arm_a, lambda c: signals(c, "console", "over_rate") > 1000)
        arm_a.daemon.stop()
    finally:
        stop.set()
        flooding.join()
    text = arm_a.daemon.log_text()
    assert "Traceback" not in text and "Event loop is closed" not in text, text[-3000:]
