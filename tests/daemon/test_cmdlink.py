"""The real-time process's messages to the command daemon never block it and are never dropped
unsaid: a full link keeps them waiting in order; beyond `OUTBOX_MAX` the oldest push goes first,
counted by kind and told to the command daemon (`link_discarded`); a one-way request's success
gets no reply."""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

from orccadd.daemon import cmdlink
from orccadd.daemon.cmdlink import CommandLink, one_way


def sender(conn: socket.socket, tmp: Path) -> CommandLink:
    """The link, with `conn` as the command daemon's connection."""
    link = CommandLink(str(tmp / "orccadd.sock.rt"))
    link.conn = conn
    return link


def received(s: socket.socket) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    while True:
        try:
            out.append(json.loads(s.recv(1 << 20)))
        except BlockingIOError:
            return out


def test_a_full_link_keeps_messages_in_order_then_counts_what_it_discards(
    monkeypatch: Any, tmp_path: Path
) -> None:
    monkeypatch.setattr(cmdlink, "OUTBOX_MAX", 50)
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    a.setblocking(False)
    b.setblocking(False)
    a.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
    p = sender(a, tmp_path)
    sent = 0
    while not p.outbox:  # until the link is full
        sent += 1
        p._send({"push": "cell_output", "name": "Pong", "n": sent})
    p._send({"id": 7, "ok": True, "result": {"applied_at_tick": 3}})  # a reply, waiting too
    for _ in range(100):  # 100 more outputs: 50 wait at most, the oldest pushes discarded
        sent += 1
        p._send({"push": "cell_output", "name": "Pong", "n": sent})
    assert len(p.outbox) == 50 and "reply" in p.outbox_kinds
    got: list[dict[str, Any]] = []
    while p.outbox or p.discarded_told != sum(p.discarded.values()):
        got += received(b)
        p._flush()
    got += received(b)
    pushes = [m["n"] for m in got if m.get("push") == "cell_output"]
    assert pushes == sorted(pushes)  # in order
    assert [m for m in got if m.get("id") == 7]  # the reply kept
    told = [m for m in got if m.get("push") == "link_discarded"]
    assert told and told[-1]["counts"] == {"cell_output": sent - len(pushes)} == p.discarded
    p.close()  # the connection `a` and the listener
    b.close()


def test_one_way_ids() -> None:
    assert one_way(-1) and not one_way(1) and not one_way(None) and not one_way(True)
