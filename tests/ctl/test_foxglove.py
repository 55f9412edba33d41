"""`orccadctl foxglove`: the WebSocket server listens on 127.0.0.1 only and stops cleanly, fed by
the monitor and events streams of a stand-in daemon (the protocol's framing, no real daemon)."""

from __future__ import annotations

import argparse
import json
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("foxglove")

from orccadd.ctl.foxglove import LiveView, run_foxglove

LABELS = ["q.j1", "q.j2", "dq.j1", "dq.j2", "tau.j1", "tau.j2", "cmd.j1", "cmd.j2"]


def listeners(port: int) -> list[str]:
    """The local addresses listening on TCP `port` (IPv4 and IPv6), from /proc/net."""
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr, _, hex_port = local.partition(":")
            if state == "0A" and int(hex_port, 16) == port:
                out.append(addr)
    return out


def refused(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


def test_the_server_listens_on_loopback_only_and_stops_cleanly() -> None:
    view = LiveView(LABELS, port=0)
    try:
        port = view.port
        assert port > 0 and listeners(port) == ["0100007F"]  # 127.0.0.1, nothing else
        view.sample(1.0, [0.1 * i for i in range(len(LABELS))])
        view.event({"kind": "instant", "seq": 3, "inputs": ["start"], "actions": ["Approach"]})
    finally:
        view.stop()
    assert not listeners(port) and refused(port)
    view.sample(1.1, [0.0] * len(LABELS))  # after stop: ignored, no error


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[str]:
    """Answers `monitor` with its header and three samples, `events` with one event, then ends."""
    path = str(tmp_path / "d.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(path)
    srv.listen()

    def answer(conn: socket.socket) -> None:
        with conn:
            req = json.loads(conn.makefile("rb").readline())
            rid = req["id"]
            if req["cmd"] == "monitor":
                items = [{"signals": ["t_s", *LABELS]}] + [
                    {"t_s": t, "values": [t] * len(LABELS)} for t in (1, 2, 3)
                ]
            else:
                items = [{"seq": 1, "kind": "command", "command": "start"}]
            lines = [{"id": rid, "ok": True, "stream": i} for i in items] + [
                {"id": rid, "ok": True, "result": {}}
            ]
            conn.sendall(b"".join((json.dumps(x) + "\n").encode() for x in lines))

    def serve() -> None:
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            threading.Thread(target=answer, args=(conn,), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    try:
        yield path
    finally:
        srv.close()


def test_orccadctl_foxglove_serves_the_stream_then_stops(
    daemon: str, capsys: pytest.CaptureFixture[str]
) -> None:
    args = argparse.Namespace(socket=daemon, port=0, rate=50.0)
    assert run_foxglove(args) == 0  # the stream ended: the server stopped
    out = capsys.readouterr().out
    port = int(out.split("ws://127.0.0.1:", 1)[1].split()[0])
    assert not listeners(port) and refused(port), (listeners(port), refused(port))
