"""The device simulators' one control protocol: requests parsed once, errors as replies."""

from __future__ import annotations

import json
from typing import Any

import pytest

from orccadd.runtime.sim_control import Injection, answer, parse_request
from orccadd.simproc import ready_fields


@pytest.mark.parametrize(
    ("line", "parsed"),
    [
        (b'{"inject": "overload", "device": 3}', Injection("overload", 3)),
        (
            b'{"inject": "stream_stall", "duration_s": 1.5}',
            Injection("stream_stall", None, {"duration_s": 1.5}),
        ),
        (
            b'{"inject": "overcurrent", "device": 2, "bus": "can1"}',
            Injection("overcurrent", 2, {"bus": "can1"}),
        ),
        (b'{"status": true}', None),
    ],
)
def test_requests_parse(line: bytes, parsed: Injection | None) -> None:
    assert parse_request(line) == parsed


@pytest.mark.parametrize(
    ("line", "words"),
    [
        (b"[1, 2]", "a JSON object"),
        (b'{"inject": 3}', "names a fault"),
        (b'{"inject": "x", "device": "3"}', "an integer"),
        (b'{"inject": "x", "device": true}', "an integer"),
        (b'{"status": 1}', '{"status": true}'),
        (b'{"statuss": true}', '{"status": true}'),
        (b"not json", "Expecting value"),
    ],
)
def test_a_bad_request_is_an_error_reply(line: bytes, words: str) -> None:
    def never(*_: Any) -> Any:
        raise AssertionError("not for a bad request")

    reply = answer(line, never, never)
    assert reply["ok"] is False and words in reply["error"]
    json.dumps(reply)  # a reply is JSON


def test_a_simulator_refusing_an_injection_says_why() -> None:
    def inject(req: Injection) -> None:
        raise ValueError(f"unknown fault {req.fault!r}")

    assert answer(b'{"inject": "meteor"}', inject, dict) == {"ok": False, "error": "unknown fault 'meteor'"}
    assert answer(b'{"status": true}', inject, lambda: {"q_rad": [0.0]}) == {"ok": True, "q_rad": [0.0]}


def test_ready_lines_give_their_fields() -> None:
    assert ready_fields("drivesim: ready, control 127.0.0.1:4711") == {"control": "127.0.0.1:4711"}
    line = "dxlsim: ready, port /tmp/x/ttyDXL, control /tmp/x/control.sock\n"
    assert ready_fields(line) == {"port": "/tmp/x/ttyDXL", "control": "/tmp/x/control.sock"}
