"""A certificate of the cell's authority that is not the named daemon's cannot answer for it:
the read-only viewer and a certificate no config lists both answer a console's requests to
arm-b (with its request id, as arm-b would) and declare liveliness tokens for arm-b and for a
robot that does not exist. The console takes arm-b's own answers only: an abort it reports is
arm-b's, and with arm-b gone an abort is not confirmed (words and exit status)."""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.cellnet.conftest import Member, console_file, free_port, start_member
from tests.cellnet.test_console import ctl
from tests.cellnet.test_hostile_peers import peer_session

zenoh = pytest.importorskip("zenoh")

IMPOSTORS = ("viewer", "stranger")  # the read role; the authority's certificate, listed nowhere


def _answer_as_arm_b(q: Any) -> None:
    """Reply success to any request, with its id, as a daemon would."""
    try:
        rid = json.loads(q.payload.to_bytes())["id"]
    except (ValueError, KeyError, TypeError, AttributeError):
        rid = 0
    fake = {"state": "idle", "mission": None, "result": "none", "faulted": False, "aborted": True}
    q.reply(q.key_expr, json.dumps({"id": rid, "ok": True, "result": fake}))


@pytest.fixture
def arm_b(tmp_path: Path, certs: Path) -> Iterator[Member]:
    m = start_member(tmp_path, "test", "arm-b", certs, [], control=("console",), read=("viewer",))
    try:
        yield m
    finally:
        m.daemon.stop()


def impostors(certs: Path, endpoint: str) -> list[Any]:
    """Each impostor a peer of the cell answering for arm-b and showing a robot `ghost`; it also
    listens, so that a console can reach it when arm-b is gone."""
    kept: list[Any] = []
    for name in IMPOSTORS:
        s = peer_session(certs, name, endpoint)
        kept.append(s)
        for chunk in ("control", "read"):
            kept.append(s.declare_queryable(f"orccadd/test/arm-b/{chunk}", _answer_as_arm_b))
        kept.append(s.liveliness().declare_token("orccadd/test/ghost/alive"))
        kept.append(s.liveliness().declare_token("orccadd/test/arm-b/alive"))
    return kept


def _close(kept: list[Any]) -> None:
    for k in reversed(kept):
        with contextlib.suppress(Exception):  # best effort at teardown
            k.undeclare() if hasattr(k, "undeclare") else k.close()


def test_only_arm_b_answers_for_arm_b(tmp_path: Path, certs: Path, arm_b: Member) -> None:
    kept = impostors(certs, arm_b.endpoint)
    try:
        console = console_file(tmp_path, "test", "console", certs, [arm_b.endpoint], daemons=("arm-b",))
        r = ctl("--cell", str(console), "--robot", "arm-b", "--json", "load", "demo")
        assert json.loads(r.stdout)["ok"], r.stdout + r.stderr
        assert arm_b.daemon.call("describe")["mission"] is not None  # arm-b's own answer: loaded
        r = ctl("--cell", str(console), "--robot", "arm-b", "--json", "status")
        status = json.loads(r.stdout)["result"]
        assert status["mission"] is not None, status  # arm-b's: the impostors say none
        listed = json.loads(ctl("--cell", str(console), "cell", "status", "--json").stdout)["robots"]
        assert sorted(listed) == ["arm-b"], listed  # no ghost
    finally:
        _close(kept)


def test_an_abort_without_arm_b_is_not_confirmed(tmp_path: Path, certs: Path) -> None:
    """arm-b is not there; the impostors are, and answer `abort` with success."""
    listen = f"tls/127.0.0.1:{free_port()}"
    kept: list[Any] = []
    try:
        host = peer_session_listening(certs, "stranger", listen)
        kept.append(host)
        kept += impostors(certs, listen)
        console = console_file(tmp_path, "test", "console", certs, [listen], daemons=("arm-b",))
        for cmd in ("abort", "hold"):
            r = ctl("--cell", str(console), "--robot", "arm-b", cmd)
            assert r.returncode != 0, (cmd, r.stdout, r.stderr)
            assert f"{cmd} NOT confirmed by arm-b" in r.stderr, r.stderr
        r = ctl("--cell", str(console), "cell", "status")
        assert r.returncode != 0 and "ghost" not in r.stdout + r.stderr, r
        assert "arm-b            LOST" in r.stdout, r.stdout  # the console's daemon, not online
    finally:
        _close(kept)


def peer_session_listening(certs: Path, name: str, endpoint: str) -> Any:
    from orccadd.cellnet.zconfig import to_json5, zenoh_config
    from orccadd.config.cellnet import load_cellnet

    raw = {"name": "test", "robot": name, "listen": [endpoint], "ca": str(certs / "ca.pem"),
           "certificate": str(certs / f"{name}.pem"), "private_key": str(certs / f"{name}.key")}  # fmt: skip
    s = zenoh.open(zenoh.Config.from_json5(to_json5(zenoh_config(load_cellnet(raw, "<test>", name), False))))
    time.sleep(0.2)
    return s
