"""The JSON protocol fuzzed over the real socket of ONE running orccadd (sim-ur5e, 500 Hz).

Requests come from the command table (every command, valid and broken arguments, ids of every
type), framed well or badly (pipelined lines, lines in pieces, oversized and unterminated lines,
non-JSON and non-UTF-8 bytes). Properties: every well-framed line gets exactly one final reply,
a JSON object with the request's id, `ok` true or a plain error message; a malformed framing
closes at most that connection; afterwards both processes are the same ones, their log holds no
traceback, and the loop kept its rate (order of magnitude only: this VM is noisy).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
from hypothesis import given
from hypothesis import strategies as st

from orccadd.ctl.client import Client
from tests.daemon.conftest import Daemon
from tests.fuzz.conftest import fuzz
from tests.fuzz.strategies import connections
from tests.fuzz.target import SECRET, check_reply, exchange, hostile_paths, start_fuzz_daemon

RATE_HZ = 500.0  # sim-ur5e's control rate


@dataclass
class Target:
    daemon: Daemon
    paths: list[str]  # hostile mission paths for `load`
    rt_pid: int
    cmdd_pid: int


@pytest.fixture(scope="module")
def target(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Target]:
    tmp = tmp_path_factory.mktemp("fuzzd")
    d = start_fuzz_daemon(tmp)
    try:
        ping = d.call("ping")
        assert isinstance(ping, dict)
        yield Target(d, hostile_paths(tmp), d.proc.pid, int(ping["pid"]))
    finally:
        d.stop()


def snapshot(d: Daemon) -> tuple[float, int]:
    s = d.status()
    return time.monotonic(), int(str(s["ticks"]))


def assert_healthy(t: Target, since: tuple[float, int]) -> None:
    """Same processes, no traceback in their log, the loop ran at its rate since `since`."""
    d = t.daemon
    assert d.proc.poll() is None, f"orccadd exited:\n{d.log.read_text()[-3000:]}"
    ping = d.call("ping")
    assert isinstance(ping, dict) and ping["pid"] == t.cmdd_pid, "the command daemon was restarted"
    now, ticks = snapshot(d)
    expected = (now - since[0]) * RATE_HZ
    assert 0.1 * expected <= ticks - since[1] <= 10 * expected, (ticks - since[1], expected)
    status = d.status()
    assert float(str(status["heartbeat_age_s"])) < 5.0, status
    log = d.log.read_text()
    assert "Traceback" not in log, log[-5000:]


def test_load_refuses_hostile_paths_without_reading_them(target: Target) -> None:
    since = snapshot(target.daemon)
    with Client(target.daemon.socket) as c:
        for p in target.paths:
            r = c.reply("load", path=p)
            check_reply(r, c.next_id, repr(p).encode())
            assert r["ok"] is False, (p, r)
            assert "mission_dirs" in r["error"] or "no such mission file" in r["error"], (p, r)
            assert SECRET not in r["error"]
    assert_healthy(target, since)


def test_fuzzed_requests_each_get_one_well_formed_reply(target: Target) -> None:
    since = snapshot(target.daemon)

    @fuzz(max_examples=100)
    @given(data=st.data())
    def one_connection(data: st.DataObject) -> None:
        frames = data.draw(connections(target.paths), label="frames")
        out = exchange(target.daemon.socket, frames)
        if out.closed:  # the daemon still serves a new connection
            ping = target.daemon.call("ping")
            assert isinstance(ping, dict) and ping["pid"] == target.cmdd_pid

    one_connection()
    assert_healthy(target, since)


def test_still_healthy_afterwards(target: Target) -> None:
    """After both tests: the daemon is the same one and still at rate (a late crash shows here)."""
    since = snapshot(target.daemon)
    time.sleep(0.5)
    assert_healthy(target, since)
