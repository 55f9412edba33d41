"""The protocol fuzzer's target: one orccadd on a private socket, the raw exchange of one fuzzed
request and the properties its replies must have. Used by `test_protocol_fuzz.py` and by
`benchmarks/fuzz.py`.

The daemon runs WITHOUT `--allow-fault-injection`: `inject` is fuzzed like any other command and
must be refused, so a fuzzed request never stalls the loop on purpose.
"""

from __future__ import annotations

import json
import math
import os
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.daemon.conftest import Daemon, robot_config
from tests.fuzz.strategies import Frame

REPLY_TIMEOUT_S = 20.0  # a reply later than this is a hang (a `load` compiles in ≤ 2 s here)
STREAM_LIMIT_S = 30.0  # a (bounded) stream's final reply later than this is a hang too
SECRET = "orccadd-fuzz-secret-3f9c1e"  # the content of a file `load` must never show


def start_fuzz_daemon(tmp: Path) -> Daemon:
    """orccadd on sim-ur5e in `tmp/daemon` (socket, log, config), missions from the shipped and
    test directories and `tmp/daemon`; fault injection NOT allowed. Up and answering
    (`Daemon.stop()` ends it)."""
    home = tmp / "daemon"
    (home / "missions").mkdir(parents=True, exist_ok=True)
    config = robot_config(home)  # mission_dirs: the shipped and test directories, and `home`
    return Daemon(config, home / "run" / "orccadd.sock", home / "orccadd.log", up_timeout_s=60.0)


def hostile_paths(tmp: Path) -> list[str]:
    """Paths `load` must refuse without showing what they hold (after `start_fuzz_daemon(tmp)`):
    links out of a mission directory, `..`, over-long names, a directory, a FIFO, system files."""
    outside = tmp / "outside"  # in no mission directory
    outside.mkdir(exist_ok=True)
    secret = outside / "secret.mission"
    secret.write_text(f"mission {SECRET}\n{SECRET}\n")
    md = tmp / "daemon" / "missions"
    links = {
        "to-secret.mission": secret,
        "to-shadow.mission": Path("/etc/shadow"),
        "to-passwd.mission": Path("/etc/passwd"),
        "to-outside": outside,
        "loop-a.mission": md / "loop-b.mission",
        "loop-b.mission": md / "loop-a.mission",
        "dangling.mission": md / "absent.mission",
    }
    for name, target in links.items():
        link = md / name
        if not link.is_symlink():
            link.symlink_to(target)
    (md / "dir.mission").mkdir(exist_ok=True)
    fifo = md / "fifo.mission"
    if not fifo.exists():
        os.mkfifo(fifo)
    long = "x" * 300
    return [
        *(str(md / n) for n in links),
        str(md / "to-outside" / "secret.mission"),
        str(md / "dir.mission"),
        str(fifo),
        str(md / ".." / "outside" / "secret.mission"),
        f"{md}/../../../../../../../../etc/shadow",
        "/etc/shadow",
        "/etc/passwd",
        "/proc/self/environ",
        "/dev/zero",
        str(secret),
        f"{md}/{long}.mission",
        f"{md}/{long}/{long}/{long}",
        "/" + "/".join(["a" * 255] * 20),
        "missions/../../etc/shadow",
        "",
        ".",
        "~root/.bashrc",
        f"{md}/\u00e9\u2603.mission",
        f"{md}/a\x00b.mission",  # not a path the OS takes
        f"{md}/\ud800.mission",  # not encodable
    ]


@dataclass
class Outcome:
    """What came back for one fuzzed request (counts for the benchmark)."""

    lines: int = 0  # well-framed request lines sent
    replies: list[dict[str, Any]] = field(default_factory=list)  # final replies, in order
    streamed: int = 0  # stream lines
    closed: bool = False  # the daemon closed the connection


def expected_id(payload: bytes) -> Any:
    """The id a reply must carry: the request's own, if it is a JSON object with a valid id (the
    protocol's: an integer within ±2^53, a finite number, or a string of at most 256 characters);
    else null (NaN or Infinity echoed would not be JSON)."""
    try:
        msg = json.loads(payload)
    except (ValueError, RecursionError):
        return None
    rid = msg.get("id") if isinstance(msg, dict) else None
    if isinstance(rid, bool) or not isinstance(rid, str | int | float):
        return None
    if isinstance(rid, float) and not math.isfinite(rid):
        return None
    if isinstance(rid, int) and not -(2**53) <= rid <= 2**53:
        return None
    return None if isinstance(rid, str) and len(rid) > 256 else rid


def same_id(a: Any, b: Any) -> bool:
    return type(a) is type(b) and a == b


def check_reply(reply: Any, rid: Any, sent: bytes) -> None:
    """A final reply: a JSON object with the request's id, ok true or a plain error message.
    Messages: `<property>: <details>` (the benchmark groups violations by property)."""
    req = f"request {sent[:300]!r}"
    assert isinstance(reply, dict), f"reply is not an object: {reply!r} to {req}"
    got = reply.get("id")
    assert same_id(got, rid), f"reply without the request's id: {got!r} instead of {rid!r} to {req}"
    assert reply.get("ok") in (True, False), f"reply without ok: {str(reply)[:300]} to {req}"
    if not reply["ok"]:
        err = reply.get("error")
        assert isinstance(err, str) and err, f"error reply without a message: {reply!r} to {req}"
        assert "Traceback" not in err, f"traceback in the reply: {err[:2000]} to {req}"
        assert "internal error" not in err, f"a handler failed: {err[:2000]} to {req}"
        assert SECRET not in err and "root:" not in err, f"file content in the reply: {err[:500]} to {req}"
        if parses(sent):
            assert not err.startswith("not JSON"), f"valid JSON refused as not JSON: {err[:300]} to {req}"


def parses(payload: bytes) -> bool:
    try:
        json.loads(payload)
        return True
    except (ValueError, RecursionError):
        return False


class Wire:
    """One raw connection; reads reply lines with a deadline."""

    def __init__(self, path: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(REPLY_TIMEOUT_S)
        self.sock.connect(path)
        self.buf = b""

    def close(self) -> None:
        self.sock.close()

    def send(self, data: bytes) -> bool:
        """False if the daemon had closed its end (it may, after an oversized line)."""
        try:
            self.sock.sendall(data)
            return True
        except (BrokenPipeError, ConnectionResetError):
            return False

    def line(self) -> bytes | None:
        """The next line, or None at end of stream; `TimeoutError` past the deadline."""
        while b"\n" not in self.buf:
            try:
                chunk = self.sock.recv(1 << 16)
            except ConnectionResetError:
                chunk = b""
            if not chunk:
                return None
            self.buf += chunk
        line, _, self.buf = self.buf.partition(b"\n")
        return line


def exchange(path: str, frames: list[Frame], out: Outcome | None = None) -> Outcome:
    """Send `frames` on one new connection, check every reply (`check_reply`), and that the
    connection is closed when, and only when, the protocol says so. `out` counts what was
    exchanged (also when a check fails)."""
    out = Outcome() if out is None else out
    w = Wire(path)
    try:
        for f in frames:
            for chunk in f.chunks:
                if not w.send(chunk):
                    assert f.kind == "oversized", f"connection closed early: before {chunk[:200]!r}"
                    break
            if f.kind in ("line", "split"):
                for payload in f.payloads:
                    out.lines += 1
                    _final_reply(w, payload, out)
            elif f.kind == "oversized":
                r = w.line()
                assert r is not None, "oversized line: closed without an error reply"
                reply = json.loads(r)
                assert reply.get("ok") is False and "longer than" in reply.get("error", ""), (
                    f"oversized line: not refused as such: {reply!r}"
                )
                assert w.line() is None, "oversized line: the connection stays open"
                out.closed = True
                return out
            else:  # "truncated": the line never ends, the client shuts its side
                w.sock.shutdown(socket.SHUT_WR)
                assert w.line() is None, f"truncated last line answered: {f.chunks[0][:200]!r}"
                out.closed = True
                return out
    finally:
        w.close()
    return out


def _final_reply(w: Wire, payload: bytes, out: Outcome) -> None:
    rid = expected_id(payload)
    end = time.monotonic() + STREAM_LIMIT_S
    while True:
        assert time.monotonic() < end, f"no final reply in {STREAM_LIMIT_S:g} s: to {payload[:300]!r}"
        raw = w.line()
        assert raw is not None, f"connection closed without a reply: to {payload[:300]!r}"
        reply = json.loads(raw)
        if isinstance(reply, dict) and "stream" in reply and reply.get("ok") is True:
            assert same_id(reply.get("id"), rid), f"stream line without the request's id: {reply!r}"
            out.streamed += 1
            continue
        out.replies.append(reply)
        check_reply(reply, rid, payload)
        return
