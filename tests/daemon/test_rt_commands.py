"""The real-time process's request handling: whatever a handler does, the reply carries the id."""

from __future__ import annotations

import json
import time
from typing import Any

import pytest

from orccadd.daemon.cmdlink import CommandLink, decode
from orccadd.daemon.machine import Machine
from orccadd.daemon.replies import CommandError, Pending
from tests.daemon.conftest import ROOT


class Broken:
    """A machine whose commands fail in every way a handler can."""

    def command(self, cmd: str, args: dict[str, Any]) -> dict[str, Any]:
        if cmd == "hold":
            raise CommandError("cannot hold while idle")
        if cmd == "abort":
            raise ZeroDivisionError("a bug")
        if cmd == "resume":
            raise RecursionError("maximum recursion depth exceeded")
        return {"done": cmd}


def handle(msg: object) -> tuple[Any, dict[str, Any]]:
    """The message as it arrives: decoded and checked once (`decode`), then handled."""
    link = CommandLink.__new__(CommandLink)  # its request handling alone: no socket
    link.machine = Broken()  # type: ignore[assignment]
    req = decode(json.dumps(msg).encode())
    if isinstance(req, dict):  # refused by the checks: never reaches the machine
        return req["id"], req
    rid, reply = link.handle(req)
    assert isinstance(reply, dict)
    return rid, reply


def test_a_refusal_and_a_bug_both_answer_with_the_request_id() -> None:
    assert handle({"id": 3, "cmd": "hold", "args": {}})[1] == {
        "id": 3,
        "ok": False,
        "error": "cannot hold while idle",
    }
    _, reply = handle({"id": "x", "cmd": "abort", "args": {}})
    assert reply["id"] == "x" and not reply["ok"] and "internal error: ZeroDivisionError" in reply["error"]
    _, reply = handle({"id": 5, "cmd": "resume", "args": {}})
    assert reply["id"] == 5 and not reply["ok"]
    assert handle({"id": 9, "cmd": "start", "args": {}})[1] == {
        "id": 9,
        "ok": True,
        "result": {"done": "start"},
    }


def test_requests_the_table_refuses_never_reach_the_machine() -> None:
    _, reply = handle({"id": 1, "cmd": "status", "args": {}})  # the command daemon's, not ours
    assert not reply["ok"] and "not a command of the real-time process" in reply["error"]
    _, reply = handle({"id": 2, "cmd": "tune", "args": {"path": "A.b.c", "value": 1e308 * 10}})
    assert not reply["ok"] and "finite" in reply["error"]
    _, reply = handle({"id": 4, "cmd": "inject", "args": {"fault": "meteor"}})
    assert not reply["ok"] and "must be one of" in reply["error"]


def test_a_compiler_answer_this_daemon_cannot_read_is_refused_saying_why(
    machine: Machine, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compile child runs the code on disk; upgraded under a running daemon, its answer names
    a class this daemon's code lacks (seen in a soak: `Can't get attribute '_Shared'`): `load` is
    refused saying what to do, not answered with an internal error."""
    from orccadd.daemon import loader

    def newer_code(data: bytes) -> object:
        raise AttributeError("Can't get attribute '_Shared' on <module 'orccadd.automaton.language.kernel'>")

    with machine.reactor.held():
        reply = machine.command("load", {"path": str(ROOT / "configs/missions/demo.mission")})
    assert isinstance(reply, Pending)
    monkeypatch.setattr(loader.pickle, "loads", newer_code)
    deadline = time.monotonic() + 60
    with pytest.raises(CommandError, match="cannot be read by this daemon .*restart it"):
        while reply.poll() is None:
            assert time.monotonic() < deadline, "the mission did not compile"
            time.sleep(0.05)


def test_a_replaced_mission_is_freed_though_the_collector_is_off(machine: Machine) -> None:
    """The real-time process runs with the automatic garbage collector off (no pause in a tick):
    a replaced mission's tasks, whose modules and ports form reference cycles and hold native
    state (Ruckig), were never freed (0.6 MB a load: 47 MB/h in the soak's reload loop)."""
    import gc
    import weakref

    def load() -> None:
        with machine.reactor.held():
            reply = machine.command("load", {"path": str(ROOT / "configs/missions/demo.mission")})
        deadline = time.monotonic() + 60
        while isinstance(reply, Pending):
            assert time.monotonic() < deadline
            time.sleep(0.05)
            reply = reply.poll() or reply

    was_enabled = gc.isenabled()
    gc.disable()
    try:
        load()
        assert machine.mission.mission is not None
        first = [weakref.ref(t) for t in machine.mission.mission.tasks]
        load()
        assert all(r() is None for r in first), "the replaced mission's tasks are still alive"
    finally:
        if was_enabled:
            gc.enable()
