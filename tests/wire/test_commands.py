"""The command table: one declaration per command, from which checks, dispatch and docs derive."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from orccadd.cmdd.server import CommandDaemon
from orccadd.daemon.commands import RtCommands
from orccadd.wire.commands import COMMANDS, Dispatcher, ProtocolError, handles, parse_request, request_id

ROOT = Path(__file__).resolve().parents[2]


def req(cmd: str, **args: Any) -> bytes:
    return json.dumps({"id": 7, "cmd": cmd, "args": args}).encode()


def test_every_command_has_exactly_one_handler_on_its_side() -> None:
    rt = Dispatcher(RtCommands(None), "rt")  # type: ignore[arg-type]
    cmdd = Dispatcher(CommandDaemon.__new__(CommandDaemon), "cmdd")
    assert set(rt.handlers) | set(cmdd.handlers) == set(COMMANDS)
    assert not set(rt.handlers) & set(cmdd.handlers)


def test_a_side_missing_a_handler_or_serving_the_other_sides_is_refused() -> None:
    class Partial:
        @handles("describe")
        def describe(self) -> None: ...

    with pytest.raises(TypeError, match="no handler for .*'load'"):
        Dispatcher(Partial(), "rt")

    class Wrong:
        @handles("ping")
        def ping(self) -> None: ...

    with pytest.raises(TypeError, match="not this side's: \\['ping'\\]"):
        Dispatcher(Wrong(), "rt")
    with pytest.raises(KeyError, match="no such command"):
        handles("teleport")


@pytest.mark.parametrize(
    ("line", "error"),
    [
        (req("tune", path="A.b.c", value=10**30), "integer out of range"),
        (b'{"cmd": "tune", "args": {"path": "A.b.c", "value": 1e999}}', "not a finite number"),
        (b'{"cmd": "tune", "args": {"path": "A.b.c", "value": NaN}}', "not a finite number"),
        (req("tune", path="A.b.c", value=[[1.0]]), "nested lists"),
        (req("tune", path="A.b.c", value=[1.0, "2"]), "list items must be a number, not a string"),
        (req("tune", path="A.b.c", value=[1.0, True]), "list items must be a number, not bool"),
        (req("monitor", signals=["q", 3]), "list items must be a string, not a number"),
        (req("tune", path="A.b.c"), "'value' is required"),
        (req("inject", fault="meteor"), "must be one of resource, overrun"),
        (req("events", follow=1), "must be a boolean"),
        (req("start", procedure=True), "must be a string, not a boolean"),
        (req("status", verbose=True), "unknown argument 'verbose'"),
        (b"[" * 100_000 + b"]" * 100_000, "not JSON"),
        (b'{"id": {"a": 1}, "cmd": "ping"}', "'id' must be"),
        (b'{"id": NaN, "cmd": "ping"}', "'id' must be a finite number"),  # echoed, it would not be JSON
        (b'{"id": -Infinity, "cmd": "ping"}', "'id' must be a finite number"),
        (b'{"id": "' + b"x" * 300 + b'", "cmd": "ping"}', "'id' must be at most 256"),
        (req("events", last=1.5), "'last' must be an integer, not 1.5"),  # was: "a number, not a number"
    ],
)
def test_malformed_arguments_are_refused_in_the_clients_terms(line: bytes, error: str) -> None:
    with pytest.raises(ProtocolError, match=error):
        parse_request(line)


def test_an_id_a_reply_cannot_echo_as_json_is_not_echoed() -> None:
    assert [request_id(json.loads(x)) for x in ('{"id": NaN}', '{"id": 1e999}', '{"id": 3}', "[1]")] == [
        None,
        None,
        3,
        None,
    ]


def test_a_well_formed_request_passes() -> None:
    assert parse_request(req("tune", path="A.b.c", value=[1, 2.5])) == (
        7,
        "tune",
        {"path": "A.b.c", "value": [1, 2.5]},
    )


def test_the_protocol_document_lists_the_table() -> None:
    out = subprocess.run([sys.executable, "tools/protocol_doc.py", "--check"], cwd=ROOT, timeout=60)
    assert out.returncode == 0, "docs/protocol.md is out of date: run python tools/protocol_doc.py"


def test_orccadctl_help_is_the_tables() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "orccadd.cli", "abort", "--help"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert COMMANDS["abort"].help.replace("`", "") in " ".join(out.stdout.split())


def test_a_request_of_another_protocol_version_is_refused_naming_both() -> None:
    from orccadd.wire.schema import PROTOCOL_VERSION

    ok = {"id": 1, "cmd": "status", "args": {}}
    assert parse_request(json.dumps(ok).encode())[1] == "status"  # no version: accepted
    assert parse_request(json.dumps({**ok, "protocol": PROTOCOL_VERSION}).encode())[1] == "status"
    old = json.dumps({**ok, "protocol": PROTOCOL_VERSION - 1}).encode()
    with pytest.raises(
        ProtocolError, match=rf"speaks protocol {PROTOCOL_VERSION}, the client {PROTOCOL_VERSION - 1}"
    ):
        parse_request(old)


def test_urgency_and_reply_times_are_declared_once_in_the_table() -> None:
    from orccadd.config.robot import DaemonConfig
    from orccadd.wire.commands import CLIENT_MARGIN_S, LOAD_TIMEOUT_MAX_S, URGENT_COMMANDS

    assert {"abort", "stop"} == URGENT_COMMANDS  # the table's `urgent` flags
    for spec in COMMANDS.values():  # the client always waits longer than the daemon may take
        assert spec.client_wait_s == spec.reply_s + CLIENT_MARGIN_S > spec.reply_s > 0
    # a load may take the longest `daemon.load_timeout_s` a config may set: its refusal arrives
    _, most = DaemonConfig.__dataclass_fields__["load_timeout_s"].metadata["bounds"]
    assert most == LOAD_TIMEOUT_MAX_S < COMMANDS["load"].reply_s
