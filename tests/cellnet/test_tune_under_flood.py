"""Every answer to a `tune` sent through the cell is true while a control peer floods signals
(issue 40): each tune applied is answered ok with the tick that applied it, and no answer claims
a failure for a tune that was applied; the real-time process's word of the mission's outputs is
published or counted, never lost unsaid (`link.discarded`)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from orccadd.cellnet.console import CellConsole, read_console_config
from tests.cellnet.conftest import Member, console_file, start_member
from tests.cellnet.test_floods import BLOCK, accounted, console, ping, run, signals, wait_cell
from tests.cellnet.test_hostile_peers import peer_session
from tests.daemon.conftest import ROOT

__all__ = ["console"]  # a fixture

TUNES = 120

TUNE_ECHO = f"""
mission TuneEcho

resource arm
input Stop
input Ping from "console"
output Pong to cell

task Reach on arm from "{ROOT / "configs/tasks/move_joints.toml"}"
  set traj.target_rad = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
  post
end

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


@pytest.fixture
def arm_a(tmp_path: Path, certs: Path) -> Iterator[Member]:
    """arm-a taking its bound's most of a control peer's signals (`signal_rate_hz` 1000): the
    link to the real-time process at its busiest."""
    m = start_member(
        tmp_path,
        "test",
        "arm-a",
        certs,
        [],
        control=("console",),
        read=("viewer",),
        extra="signal_rate_hz = 1000\nsignal_burst = 1000\n",
    )
    try:
        yield m
    finally:
        m.daemon.stop()


class Flood:
    """A control peer putting `Ping` as fast as it can, from `start` until `stop`."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self.halt = threading.Event()
        self.thread = threading.Thread(target=self._put)

    def _put(self) -> None:
        pub = self.session.declare_publisher("orccadd/test/console/signal/Ping", congestion_control=BLOCK)
        n = 0
        while not self.halt.is_set():
            n += 1
            pub.put(ping(n))
        pub.undeclare()

    def start(self) -> None:
        self.thread.start()

    def stop(self) -> None:
        self.halt.set()
        if self.thread.is_alive():
            self.thread.join()


@pytest.fixture
def flood(certs: Path, arm_a: Member, console: Any) -> Iterator[Flood]:
    """The flood from a session of its own: the console's liveliness token (`console`) stays on
    a link the flood does not choke (a flooding session's link can close after its lease)."""
    session = peer_session(certs, "console", arm_a.endpoint)
    f = Flood(session)
    try:
        yield f
    finally:
        f.stop()
        session.close()


def test_every_tune_answer_under_a_signal_flood_is_true(
    tmp_path: Path, certs: Path, arm_a: Member, flood: Flood
) -> None:
    run(arm_a, "tune_echo", TUNE_ECHO)
    flood.start()
    wait_cell(arm_a, lambda c: signals(c, "console", "over_rate") > 1000)  # flooding
    path = console_file(tmp_path, "test", "console", certs, [arm_a.endpoint], daemons=("arm-a",))
    replies: list[dict[str, Any]] = []
    with CellConsole(read_console_config(str(path))) as con:
        for i in range(TUNES):
            replies.append(con.request("arm-a", "tune", path="Reach.ct.kp[2]", value=500.0 + i))
    flood.stop()
    # every answer true: each tune applied says so, with its tick, as the trace does
    wrong = [(i, r) for i, r in enumerate(replies) if not r.get("ok")]
    assert not wrong, wrong[:5]
    traced = {
        e["tune"]["new"][0]: e["tune"]["tick"]
        for e in arm_a.daemon.call("events", last=100_000)["events"]  # type: ignore[index]
        if e.get("tune")
    }
    ticks = [r["result"]["applied_at_tick"] for r in replies]
    assert ticks == sorted(ticks)
    for i, tick in enumerate(ticks):  # those the trace ring still holds
        assert traced.get(500.0 + i, tick) == tick, (i, tick, traced.get(500.0 + i))
    # every output of every Ping taken published, or counted lost; lost only if the real-time
    # process's link discarded its word of it (counted there too)
    assert arm_a.daemon.status()["state"] == "running"  # every Ping taken answered with a Pong
    st = arm_a.daemon.wait(lambda st: accounted(st["cell"], signals(st["cell"], "console", "taken")))
    lost = st["cell"]["outputs"]["lost"]
    assert not lost or st["rt_link"]["discarded"].get("cell_output", 0) > 0, (st["cell"], st["rt_link"])
    assert st["rt_link"]["late_replies"] == 0, st["rt_link"]
