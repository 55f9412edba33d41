"""A command daemon's threads after many cell sessions (issue 40: "15 → 36 after 100
connections"): the growth is Zenoh's own runtime pools (`acc-N`, `net-N`, `rx-N`: tokio workers
handed off by `block_in_place` during links' handshakes), whose idle threads end after tokio's
10 s keep-alive; nothing of the daemon's own is left per session (no executor thread per query).
So the count comes back to where it was, and the Python threads never grow."""

from __future__ import annotations

import json
import os
import threading
import time
from collections import Counter
from pathlib import Path

import pytest

from tests.cellnet.conftest import Member, start_member
from tests.cellnet.test_hostile_peers import peer_session

zenoh = pytest.importorskip("zenoh")

SESSIONS = 100
AT_ONCE = 10
ZENOH_POOLS = ("acc-", "app-", "net-", "rx-", "tx-")
# the pools' workers that stay (zenoh 1.10's defaults: app 1, acc 1, tx 1, rx 2, net 1), and one
# more app thread seen at start
POOL_WORKERS = 7


def cmdd_pid(m: Member) -> int:
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"orccadd.cmdd" in argv and m.daemon.socket.encode() in argv:
            return int(pid)
    raise AssertionError("no command daemon found")


def threads(pid: int) -> Counter[str]:
    """The process's threads by kind: each Zenoh pool's, and the rest by name."""
    out: Counter[str] = Counter()
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            name = Path(f"/proc/{pid}/task/{tid}/comm").read_text().strip()
        except OSError:
            continue
        out[next((p for p in ZENOH_POOLS if name.startswith(p)), name)] += 1
    return out


def one_session(certs: Path, m: Member) -> None:
    s = peer_session(certs, "viewer", m.endpoint)
    try:
        line = json.dumps({"id": 1, "cmd": "status", "args": {}, "protocol": 1})
        replies = [r for r in s.get("orccadd/test/arm-a/read", payload=line, timeout=10.0) if r.ok]
        assert replies
    finally:
        s.close()


def pooled(counts: Counter[str]) -> int:
    return sum(n for k, n in counts.items() if k in ZENOH_POOLS)


def test_cell_sessions_leave_no_threads_behind(tmp_path: Path, certs: Path) -> None:
    m = start_member(tmp_path, "test", "arm-a", certs, [], control=("console",), read=("viewer",))
    try:
        pid = cmdd_pid(m)
        one_session(certs, m)  # the first link starts the pools' workers (rx, tx)
        python = threads(pid)["python"]  # the daemon's own: the event loop's, the executor's
        peak = 0
        for _ in range(SESSIONS // AT_ONCE):
            group = [threading.Thread(target=one_session, args=(certs, m)) for _ in range(AT_ONCE)]
            for t in group:
                t.start()
            for t in group:
                t.join()
            now = threads(pid)
            peak = max(peak, sum(now.values()))
            assert now["python"] == python, now  # nothing of the daemon's own per session
        # Zenoh's pools end their idle threads (tokio's keep-alive, 10 s): back to their workers
        deadline = time.monotonic() + 60
        while pooled(now := threads(pid)) > POOL_WORKERS and time.monotonic() < deadline:
            time.sleep(0.5)
        assert pooled(now) <= POOL_WORKERS, (now, peak)
    finally:
        m.daemon.stop()
