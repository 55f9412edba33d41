"""Streams (`events --follow`, `monitor`) as a terminal user meets them: no timeout on a quiet
daemon, a closed pipe (`| head`) ends quietly. Against a stand-in server speaking the protocol's
framing (one JSON object per line), so that the client alone is under test."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.ctl.client import Client


@pytest.fixture
def server(tmp_path: Path) -> Iterator[tuple[str, list[float]]]:
    """A UNIX socket server: to a stream request it sends one item, then `pause[0]` seconds of
    silence, then items without end (until the client goes)."""
    path = str(tmp_path / "s.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(path)
    srv.listen()
    pause = [0.0]

    def serve() -> None:
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn:
                req = json.loads(conn.makefile("rb").readline())
                item = {"id": req["id"], "ok": True, "stream": {"signals": ["q.0"]}}
                try:
                    conn.sendall((json.dumps(item) + "\n").encode())
                    time.sleep(pause[0])
                    row = {"id": req["id"], "ok": True, "stream": {"t_s": 1.0, "values": [0.5]}}
                    while True:
                        conn.sendall((json.dumps(row) + "\n").encode())
                        time.sleep(0.001)
                except OSError:
                    pass

    threading.Thread(target=serve, daemon=True).start()
    yield path, pause
    srv.close()


def test_a_stream_waits_through_silence_longer_than_the_clients_timeout(
    server: tuple[str, list[float]],
) -> None:
    path, pause = server
    pause[0] = 0.6
    with Client(path, timeout_s=0.2) as c:
        items = c.stream("monitor", signals="q")
        assert next(items) == {"signals": ["q.0"]}
        assert next(items) == {"t_s": 1.0, "values": [0.5]}  # after 0.6 s of silence: no timeout


def test_monitor_into_a_closed_pipe_ends_quietly(server: tuple[str, list[float]]) -> None:
    path, _ = server
    env = {**os.environ, "ORCCADD_SOCKET": path}
    out = subprocess.run(
        f"{sys.executable} -m orccadd.cli monitor q | head -2",
        shell=True, capture_output=True, text=True, env=env, timeout=30,
    )  # fmt: skip
    assert len(out.stdout.splitlines()) == 2
    assert "Traceback" not in out.stderr and "BrokenPipe" not in out.stderr, out.stderr


def test_the_socket_may_be_given_before_the_subcommand(server: tuple[str, list[float]]) -> None:
    path, _ = server
    env = {**os.environ, "ORCCADD_SOCKET": "/nonexistent/orccadd.sock"}  # the option wins
    out = subprocess.run(
        f"{sys.executable} -m orccadd.cli --socket {path} monitor q | head -1",
        shell=True, capture_output=True, text=True, env=env, timeout=30,
    )  # fmt: skip
    assert out.stdout.split() == ["q.0"], out.stderr
