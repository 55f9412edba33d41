"""The command daemon's link to the real-time process (`RtLink`): one-way requests from other
threads (a peer's signal from Zenoh's) each get an id of their own, in order, and go whole or not
at all: a refused one takes no id."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.cmdd.rtlink import RtLink


@pytest.fixture
def link(tmp_path: Path) -> Iterator[tuple[RtLink, socket.socket]]:
    """An `RtLink` connected to a listener standing for the real-time process; both ends."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    listener.bind(str(tmp_path / "rt.sock"))
    listener.listen(1)
    rt = RtLink(str(tmp_path / "rt.sock"))
    peer, _ = listener.accept()
    peer.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    try:
        yield rt, peer
    finally:
        rt.sock.close()
        peer.close()
        listener.close()


def test_one_way_requests_from_many_threads_each_have_an_id_of_their_own(
    link: tuple[RtLink, socket.socket],
) -> None:
    rt, peer = link
    threads_n, each = 8, 100
    sent: list[bool] = []

    refused = [0]

    def send(t: int) -> None:
        for i in range(each):
            while not rt.send_oneway("cell_input", {"input": f"s{t}_{i}", "peer": "arm-b"}):
                refused[0] += 1  # the link's buffer full for now: the caller queues and retries
                time.sleep(0.001)
            sent.append(True)

    threads = [threading.Thread(target=send, args=(t,)) for t in range(threads_n)]
    received: list[dict[str, object]] = []

    def drain() -> None:  # the real-time process reads as they come: the link's buffer never fills
        peer.settimeout(10)
        while len(received) < sent.count(True) or any(t.is_alive() for t in threads):
            try:
                received.append(json.loads(peer.recv(1 << 16)))
            except TimeoutError:
                return

    reader = threading.Thread(target=drain)
    for t in threads:
        t.start()
    reader.start()
    for t in threads:
        t.join()
    reader.join(timeout=30)
    assert len(sent) == threads_n * each
    ids = [m["id"] for m in received]
    assert sorted(ids, reverse=True) == list(range(-1, -threads_n * each - 1, -1))  # each once
    assert ids == sorted(ids, reverse=True)  # on the link in the order of their ids
    assert {m["cmd"] for m in received} == {"cell_input"}


def test_a_full_link_or_a_closed_one_refuses_a_one_way_request(link: tuple[RtLink, socket.socket]) -> None:
    rt, peer = link
    big = "x" * 60_000
    n = 0
    while rt.send_oneway("cell_input", {"input": big, "peer": "arm-b"}):  # nobody reads: it fills
        n += 1
        assert n < 10_000, "the link never filled"
    got = json.loads(peer.recv(1 << 17))
    assert got["id"] == -1 and got["args"]["input"] == big  # what went, went whole
    rt.closed = True
    assert not rt.send_oneway("cell_input", {"input": "a", "peer": "arm-b"})
