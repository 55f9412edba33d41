"""`orccadctl foxglove`: the WebSocket server listens on 127.0.0.1 only, speaks the Foxglove
WebSocket protocol to a stock WebSocket client, serves the user who started it only (not another
local user, not a page of a foreign origin) and stops cleanly, fed by the monitor and events
streams of a stand-in daemon (the protocol's framing, no real daemon)."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pwd
import socket
import struct
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("websockets")

from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

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
            line = conn.makefile("rb").readline()
            if not line:  # a client gone before asking (the viewer stopped meanwhile)
                return
            req = json.loads(line)
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
            with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # the viewer may be gone
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


def _connect(port: int, origin: str | None = None):  # type: ignore[no-untyped-def]
    return connect(
        f"ws://127.0.0.1:{port}",
        subprotocols=["foxglove.websocket.v1"],
        origin=origin,
        open_timeout=10,  # type: ignore[list-item,arg-type]
    )


def test_a_stock_client_gets_the_channels_and_the_messages_it_subscribed_to() -> None:
    view = LiveView(LABELS, port=0)
    try:
        with _connect(view.port) as ws:
            info = json.loads(ws.recv(timeout=10))
            adv = json.loads(ws.recv(timeout=10))
            assert info["op"] == "serverInfo" and adv["op"] == "advertise"
            topics = {c["topic"]: c for c in adv["channels"]}
            assert set(topics) == {"/q", "/dq", "/tau", "/cmd", "/joint_states", "/events"}
            assert topics["/joint_states"]["schemaName"] == "foxglove.JointStates"
            assert json.loads(topics["/q"]["schema"])["properties"]["j1"]["unit"] == "rad"
            subs = [
                {"id": 7, "channelId": topics["/q"]["id"]},
                {"id": 9, "channelId": topics["/events"]["id"]},
            ]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            got: dict[int, dict[str, object]] = {}
            for _ in range(200):  # the subscription is taken asynchronously: publish until seen
                view.sample(1.5, [0.1 * i for i in range(len(LABELS))])
                view.event({"kind": "instant", "seq": 3, "inputs": ["start"], "actions": ["Approach"]})
                try:
                    while len(got) < 2:
                        frame = ws.recv(timeout=0.05)
                        assert isinstance(frame, bytes) and frame[0] == 1
                        sub, _ns = struct.unpack_from("<IQ", frame, 1)
                        got[sub] = json.loads(frame[13:])
                except TimeoutError:
                    pass
                if len(got) == 2:
                    break
        assert got[7] == {"time_s": 1.5, "j1": 0.0, "j2": 0.1}, got
        assert got[9]["message"] == "start -> Approach" and got[9]["line"] == 3, got
    finally:
        view.stop()


def test_a_foreign_origin_is_refused_foxglove_and_native_clients_are_not() -> None:
    view = LiveView(LABELS, port=0)
    try:
        with pytest.raises(InvalidStatus) as e:
            _connect(view.port, origin="https://evil.example")
        assert e.value.response.status_code == 403
        for origin in (None, "https://app.foxglove.dev"):
            with _connect(view.port, origin=origin) as ws:
                assert json.loads(ws.recv(timeout=10))["op"] == "serverInfo"
    finally:
        view.stop()


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to connect as another user")
def test_another_local_user_is_refused() -> None:
    """User nobody, holding no role on the daemon, reaches 127.0.0.1 like everyone: refused."""
    view = LiveView(LABELS, port=0)
    try:
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: become nobody, try the handshake, report the status
            try:
                os.close(r)
                nobody = pwd.getpwnam("nobody")
                os.setgid(nobody.pw_gid)
                os.setuid(nobody.pw_uid)
                try:
                    with _connect(view.port):
                        status = 101
                except InvalidStatus as err:
                    status = err.response.status_code
                os.write(w, str(status).encode())
            finally:
                os._exit(0)
        os.close(w)
        with os.fdopen(r) as fh:
            status = fh.read()
        os.waitpid(pid, 0)
        assert status == "403", status
        with _connect(view.port) as ws:  # and we still are served
            assert json.loads(ws.recv(timeout=10))["op"] == "serverInfo"
    finally:
        view.stop()


def test_a_cells_channels_are_named_by_resource_and_every_joint_is_on_joint_states() -> None:
    """A cell's monitor labels (`left/q.j1`): a channel per resource and signal, with the
    signal's unit; `/joint_states` carries both arms' joints, a shared name told apart."""
    labels = ["left/q.j1", "left/q.j2", "left/tau.j1", "right/q.j1", "right/q.finger"]
    view = LiveView(labels, port=0)
    try:
        with _connect(view.port) as ws:
            json.loads(ws.recv(timeout=10))
            adv = json.loads(ws.recv(timeout=10))
            topics = {c["topic"]: c for c in adv["channels"]}
            assert set(topics) == {"/left/q", "/left/tau", "/right/q", "/joint_states", "/events"}
            assert json.loads(topics["/left/tau"]["schema"])["properties"]["j1"]["unit"] == "N.m"
            ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [{"id": 4, "channelId": topics["/joint_states"]["id"]}],
                    }
                )
            )
            states = None
            for _ in range(200):
                view.sample(2.0, [1.0, 2.0, 3.0, 4.0, 5.0])
                with contextlib.suppress(TimeoutError):
                    frame = ws.recv(timeout=0.05)
                    assert isinstance(frame, bytes)
                    states = json.loads(frame[13:])
                    break
        assert states is not None
        assert [(j["name"], j["position"], j["effort"]) for j in states["joints"]] == [
            ("left/j1", 1.0, 3.0),
            ("j2", 2.0, None),
            ("right/j1", 4.0, None),
            ("finger", 5.0, None),
        ]
    finally:
        view.stop()
