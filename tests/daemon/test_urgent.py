"""`<socket>.urgent`: abort and stop served by the real-time process itself, and nothing else."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
import time
from pathlib import Path

import pytest

from orccadd.ctl.client import Client
from orccadd.launch import DaemonError
from orccadd.wire.socketdir import urgent_socket_path
from tests.daemon.conftest import ROBOT, ROOT, Daemon, start_daemon
from tests.daemon.test_protocol import _as_nobody_many, _reachable_by_nobody
from tests.safety import assert_commands_within_limits, assert_safe_stop_in_time, from_telemetry

DEMO = str(ROOT / "configs/missions/demo.mission")


def _line(sock: socket.socket) -> dict[str, object]:
    reply: dict[str, object] = json.loads(sock.makefile("rb").readline())
    return reply


def _urgent(daemon: Daemon) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(10)
    s.connect(urgent_socket_path(daemon.socket))
    return s


def test_orccadctl_abort_goes_through_the_urgent_socket_while_clients_keep_the_daemon_busy(
    daemon: Daemon,
) -> None:
    daemon.call("load", path=DEMO)
    daemon.call("start")
    daemon.wait(lambda s: s["active_task"] == "Reach")
    stop = threading.Event()
    answered = threading.Semaphore(0)  # one release per busy client, at its first answer

    def busy() -> None:
        with Client(daemon.socket) as c:
            c.reply("params")
            answered.release()
            while not stop.is_set():
                c.reply("params")

    threads = [threading.Thread(target=busy) for _ in range(6)]
    for t in threads:
        t.start()
    try:
        for _ in threads:  # every client connected and asking before the abort
            assert answered.acquire(timeout=30), "a busy client got no answer"
        r = daemon.ctl("abort")
    finally:
        stop.set()
        for t in threads:
            t.join()
    assert r.returncode == 0, r.stderr
    s = daemon.wait(lambda s: "stopped" in s.get("resource_status", []))
    assert s["result"] == "aborted"
    assert "abort from the urgent socket: ok" in daemon.log.read_text()
    events = daemon.call("events", last=50)["events"]  # type: ignore[index]
    aborted_t_s = next(e["t_s"] for e in events if e.get("command") == "abort")
    ticks = from_telemetry(str(daemon.call("describe")["telemetry"]))  # type: ignore[index]
    assert_safe_stop_in_time(ticks, lambda i: bool(ticks.t_s[i] >= aborted_t_s))
    assert_commands_within_limits(ticks, ROBOT)


def test_the_urgent_socket_takes_abort_and_stop_only_and_bounded_lines(daemon: Daemon) -> None:
    for line, why in [
        (b'{"id": 7, "cmd": "status"}\n', "abort and stop only"),
        (b'{"id": 8, "cmd": "tune", "args": {"path": "x", "value": 1}}\n', "abort and stop only"),
        (b"not json\n", "abort and stop only"),
        (b"[" * 4000 + b"\n", "abort and stop only"),  # deep nesting, within the size
        (b"x" * 5000, "request longer than 4096 bytes"),
    ]:
        with _urgent(daemon) as s:
            s.sendall(line)
            reply = _line(s)
            assert not reply["ok"] and why in str(reply["error"]), (line[:40], reply)
            assert s.recv(1) == b""  # closed
    with _urgent(daemon) as s:  # a stop with no mission running: refused by the machine, still served
        s.sendall(b'{"id": 9, "cmd": "stop"}\n')
        reply = _line(s)
        assert reply["id"] == 9 and not reply["ok"] and "stop" in str(reply["error"])
    assert daemon.status()["state"] == "idle"


def test_a_new_connection_makes_way_for_itself_and_a_line_longer_than_4_kib_is_refused(
    daemon: Daemon,
) -> None:
    held = [_urgent(daemon) for _ in range(8)]
    try:
        with _urgent(daemon) as s:  # all places held by silent peers: the oldest makes way
            s.sendall(b'{"id": 1, "cmd": "stop"}\n')
            reply = _line(s)
            assert reply["id"] == 1 and "stop" in str(reply["error"]), reply  # served (nothing to stop)
        first = _line(held[0])
        assert not first["ok"] and "make way" in str(first["error"]), first
    finally:
        for h in held:
            h.close()
    with _urgent(daemon) as s:  # 8,094 bytes in two writes: refused, not read as a request
        body = b'{"id": 2, "cmd": "abort", "pad": "' + b"x" * 8050 + b'"}\n'
        s.sendall(body[:4000])
        time.sleep(0.1)
        s.sendall(body[4000:])
        reply = _line(s)
        assert not reply["ok"] and "longer than 4096" in str(reply["error"]), reply
    assert not daemon.status()["faulted"]


def test_abort_cannot_be_denied_by_peers_holding_every_place(daemon: Daemon) -> None:
    """The urgent places held by peers trickling a byte now and then, every control place of the
    main socket held by idle connections: `orccadctl abort` still aborts (exit 0), and a `hold`
    that cannot be delivered says so (exit 1, never 0 in silence)."""
    daemon.call("load", path=DEMO)
    stop = threading.Event()
    urgent = [_urgent(daemon) for _ in range(8)]
    main: list[socket.socket] = []

    def trickle() -> None:
        while not stop.wait(0.3):
            for s in list(urgent):
                try:
                    s.sendall(b" ")
                except OSError:  # closed to make way: reconnect and hold again
                    urgent.remove(s)
                    with contextlib.suppress(OSError):
                        urgent.append(_urgent(daemon))

    t = threading.Thread(target=trickle)
    daemon.call("start")
    try:
        t.start()
        end = time.monotonic() + 20
        while True:
            # hold a place more until none is left (the 16 are counted in turn; one connected
            # while the server still counted `start`'s closing connection got no place)
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(daemon.socket)
            main.append(s)
            if len(main) < 16:
                continue
            time.sleep(0.1)
            with Client(daemon.socket) as c:  # beyond the limit: abort and stop only
                r = c.reply("status")
            if not r["ok"] or time.monotonic() > end:
                break
        assert not r["ok"] and "too many clients" in str(r["error"]), r
        h = daemon.ctl("hold")
        assert h.returncode == 1 and "too many clients" in h.stderr, (h.returncode, h.stderr)
        r = daemon.ctl("abort")
        assert r.returncode == 0, (r.returncode, r.stdout, r.stderr)
    finally:
        stop.set()
        if t.is_alive():
            t.join()
        for s in [*urgent, *main]:
            s.close()
    st = daemon.wait(lambda st: "stopped" in st.get("resource_status", []))
    assert st["result"] == "aborted", st


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a client as another user")
def test_a_peer_without_the_control_role_is_refused(tmp_path: Path) -> None:
    _reachable_by_nobody(tmp_path)
    d = start_daemon(tmp_path, daemon_cfg='socket_group = "nogroup"\nread_groups = ["nogroup"]')
    try:
        (reply,) = _as_nobody_many(urgent_socket_path(d.socket), 1, "abort")
        assert not reply["ok"] and "need the control role" in str(reply["error"])
        assert d.status()["state"] == "idle"
    finally:
        d.stop()


def test_a_squatted_urgent_path_stops_the_daemon_before_anything_starts(tmp_path: Path) -> None:
    (tmp_path / "run").mkdir(mode=0o750)
    Path(urgent_socket_path(str(tmp_path / "run" / "orccadd.sock"))).write_text("mine")
    with pytest.raises(DaemonError, match="exists and is not a socket"):
        start_daemon(tmp_path)
