"""Hypothesis strategies of the fuzz suite: protocol requests derived from the command table
(`orccadd.wire.commands.COMMANDS`), mission texts mutated along the grammar (`mission_text`),
robot config texts mutated at the TOML-value level (`toml_text`).

Every strategy is bounded (sizes, depths, lengths), so one example takes milliseconds to
build; the large inputs (64 KiB lines, 10 000-deep nesting, 600 task calls) are built by
repetition, not drawn element by element.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from orccadd.wire.commands import COMMANDS, MAX_INT, MAX_LINE, Arg, CommandSpec
from tests.fuzz import mission_text, toml_text

# ---- JSON text ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Raw:
    """JSON text inserted verbatim (numbers Python cannot print, 10 000-deep nesting, NaN)."""

    text: str


def dump(v: Any) -> str:
    """`v` as JSON text; `Raw` verbatim, NaN/Infinity as Python's json writes them."""
    if isinstance(v, Raw):
        return v.text
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))}: {dump(x)}" for k, x in v.items()) + "}"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(dump(x) for x in v) + "]"
    return json.dumps(v)


DEEP = 10_000
EDGE_NUMBERS = [
    Raw(str(MAX_INT)), Raw(str(MAX_INT + 1)), Raw(str(-MAX_INT - 1)), Raw(str(2**63)), Raw(str(10**400)),
    Raw("9" * 5000), Raw("NaN"), Raw("Infinity"), Raw("-Infinity"), Raw("1e400"), Raw("-1e400"),
    Raw("1e-400"), Raw("-0"), Raw("0.0"), Raw("5e-324"), Raw("1.7976931348623157e308"),
]  # fmt: skip
DEEP_VALUES = [
    Raw("[" * DEEP + "]" * DEEP),
    Raw('{"a": ' * DEEP + "1" + "}" * DEEP),
    Raw("[" * 900 + "]" * 900),  # just below the interpreter's recursion limit
    Raw("[" * DEEP),  # never closed
]
# strings as JSON carries them: any code point, lone surrogates and NUL included
chars = st.characters(codec=None, exclude_categories=()) | st.characters(
    min_codepoint=0xD800, max_codepoint=0xDFFF
)
texts = st.text(chars, max_size=40) | st.sampled_from(["", ".", "..", "/", "\x00", "\u202e", "é"])
huge_texts = st.integers(1000, MAX_LINE + 1000).map(lambda n: "a" * n)
scalars = st.none() | st.booleans() | st.integers() | st.floats() | texts
json_values = st.recursive(
    scalars, lambda c: st.lists(c, max_size=4) | st.dictionaries(texts, c, max_size=4), max_leaves=12
)
any_value = json_values | st.sampled_from(EDGE_NUMBERS + DEEP_VALUES) | huge_texts

# ---- arguments from the command table --------------------------------------------------------

SIGNALS = ["q", "dq", "tau", "cmd", "q.3", "q.0", "q.9", "q.-1", "q.shoulder_pan_joint", "dq.wrist_3_joint"]
SIGNALS += ["wake_us", "compute_us", "task", "phase", "status", "zz", "q.", ".q", "q.3.1"]
TASKS = ["Hold", "Home", "Reach", "Inspect", "Approach", "Out", "Back", "KeepStableUS"]
MODULES = ["hold", "pd", "traj", "ct", "lost", "drift", "reached", "limits"]
PARAMS = ["kp", "kd", "ki", "speed_scale", "target_rad", "threshold_rad", "timeout_s", "q_rad"]
INPUTS = ["Stop", "Go", "KeepStableUS", ""]
PROCEDURES = ["PickAndInspect", "KEEPSTABLE", "Shuttle", ""]
SHIPPED_MISSIONS = sorted(
    str(p) for p in Path(__file__).resolve().parents[2].glob("configs/missions/*.mission")
)

names_from = st.sampled_from


def small_numbers() -> st.SearchStrategy[Any]:
    return (
        st.integers(-MAX_INT, MAX_INT)
        | st.integers(-10, 1000)
        | st.floats(allow_nan=False, allow_infinity=False)
        | st.floats(-1e4, 1e4, allow_nan=False)
    )


def value_of(spec: CommandSpec, a: Arg, paths: list[str]) -> st.SearchStrategy[Any]:
    """A value the table accepts for `a` (name-aware: signal names, tune paths, mission paths)."""
    if a.choices:
        return st.sampled_from(a.choices)
    name = f"{spec.name}.{a.name}"
    special: dict[str, st.SearchStrategy[Any]] = {
        "load.path": st.sampled_from(SHIPPED_MISSIONS + paths) | texts,
        "tune.path": st.builds(
            lambda t, m, p: f"{t}.{m}.{p}", names_from(TASKS), names_from(MODULES), names_from(PARAMS)
        )
        | texts,
        "tune.value": small_numbers() | st.lists(small_numbers(), max_size=8),
        "send.input": names_from(INPUTS) | texts,
        "start.procedure": names_from(PROCEDURES) | texts,
        "params.task": names_from(TASKS) | texts,
        "log.name": st.sampled_from(["run.csv", "a.csv", ".x.csv", "../x.csv", "x"]) | texts,
    }
    if name in special:
        return special[name]
    options: list[st.SearchStrategy[Any]] = []
    for t in a.types:
        if t is bool:
            options.append(st.booleans())
        elif t is int:
            options.append(st.integers(-MAX_INT, MAX_INT) | st.integers(-5, 200))
        elif t is float:
            options.append(st.floats(allow_nan=False, allow_infinity=False))
        elif t is str:
            options.append(texts)
        elif t is list:
            item = names_from(SIGNALS) if a.items == (str,) else small_numbers()
            options.append(st.lists(item | texts, max_size=6))
    return st.one_of(options)


def bounded(cmd: str, args: dict[str, Any]) -> dict[str, Any]:
    """Accepted stream requests made to end within a fraction of a second: every request must
    get its final reply, and a `monitor` or `events --follow` with no count and no duration
    never ends (a `monitor` at 0.001 Hz also sleeps 1000 s after its last sample)."""
    out = dict(args)
    num = (int, float)
    if cmd == "monitor":
        count, rate = out.get("count", 0), out.get("rate_hz", 10.0)
        if isinstance(count, int) and not isinstance(count, bool) and (count == 0 or count > 3):
            out["count"] = 2
        if isinstance(rate, num) and not isinstance(rate, bool) and 0 < rate < 50:
            out["rate_hz"] = 50.0
    if cmd == "events" and out.get("follow") is True:
        d = out.get("duration_s", 0.0)
        if isinstance(d, num) and not isinstance(d, bool) and (d == 0 or d > 0.2 or math.isnan(d)):
            out["duration_s"] = 0.1
    return out


WRONG_BY_TYPE: dict[type, st.SearchStrategy[Any]] = {
    bool: st.booleans(),
    int: st.integers(),
    float: st.floats(allow_nan=False, allow_infinity=False).filter(lambda x: not x.is_integer()),
    str: texts,
    list: st.lists(scalars, max_size=3),
    dict: st.dictionaries(texts, scalars, max_size=3),
    type(None): st.none(),
}


def wrong_value(a: Arg) -> st.SearchStrategy[Any]:
    """A value of a JSON type `a` does not accept, or a number/list the table must refuse."""
    wrong = [s for t, s in WRONG_BY_TYPE.items() if t not in a.types and not (t is float and int in a.types)]
    refused = st.sampled_from(EDGE_NUMBERS[1:] + DEEP_VALUES) | st.lists(st.lists(st.integers(), max_size=2))
    return st.one_of(*wrong, refused)


@st.composite
def request_obj(draw: st.DrawFn, paths: list[str]) -> dict[str, Any]:
    """A request object: valid for a command of the table, or broken in one or two places."""
    spec = draw(st.sampled_from(list(COMMANDS.values())))
    args: dict[str, Any] = {}
    for a in spec.args:
        if a.required or draw(st.booleans()):
            args[a.name] = draw(value_of(spec, a, paths))
    msg: dict[str, Any] = {"cmd": spec.name, "args": args}
    if draw(st.integers(0, 4)):
        msg["id"] = draw(st.integers(-1000, 10**6) | texts | st.none() | st.floats() | st.just(10**400))
    for _ in range(draw(st.integers(0, 2))):
        breakage = draw(st.integers(0, 9))
        if not isinstance(msg.get("args"), dict):  # already broken: break something else
            breakage = draw(st.sampled_from([3, 5, 6, 8]))
        else:
            args = msg["args"]
        if breakage == 0 and spec.args:
            a = draw(st.sampled_from(spec.args))
            args[a.name] = draw(wrong_value(a))
        elif breakage == 1 and spec.args:
            args.pop(draw(st.sampled_from([a.name for a in spec.args])), None)
        elif breakage == 2:
            args[draw(texts | st.just("now"))] = draw(scalars)
        elif breakage == 3:
            msg["cmd"] = draw(texts | st.sampled_from([Raw("7"), None, [spec.name], spec.name.upper()]))
        elif breakage == 4:
            msg["args"] = draw(st.sampled_from([[], "x", 1, None, Raw("[" * DEEP + "]" * DEEP)]))
        elif breakage == 5:
            msg[draw(texts.filter(lambda k: k not in ("id", "cmd", "args")))] = draw(scalars)
        elif breakage == 6:
            msg["id"] = draw(
                st.booleans() | st.lists(st.integers(), max_size=2) | st.sampled_from(DEEP_VALUES)
            )
        elif breakage == 7:
            del msg["args"]
        elif breakage == 8:
            msg.pop("cmd", None)
        else:
            args[draw(st.sampled_from([a.name for a in spec.args] or ["x"]))] = draw(any_value)
    if msg.get("cmd") == spec.name and isinstance(msg.get("args", {}), dict):
        fixed = bounded(spec.name, msg.get("args", {}))  # no stream that would never end
        if "args" in msg or fixed:
            msg["args"] = fixed
    return msg


# ---- framing -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    """Bytes for one connection step. `line`/`split`: complete lines, each answered once (split:
    written in pieces); `oversized`: a line over the bound (error reply, then closed);
    `truncated`: a last line without its newline, then the client shuts its side (no reply)."""

    kind: str
    payloads: tuple[bytes, ...]  # the lines (without newline), each answered once, in order
    chunks: tuple[bytes, ...]  # the writes

    @property
    def data(self) -> bytes:
        return b"".join(self.chunks)


def line_frame(payload: bytes) -> Frame:
    """One request line; over the bound it is an `oversized` frame (the server's rule: the
    newline must come within MAX_LINE bytes)."""
    payload = payload.replace(b"\n", b" ")
    kind = "line" if len(payload) <= MAX_LINE else "oversized"
    return Frame(kind, (payload,), (payload + b"\n",))


NON_JSON = [
    b"", b" ", b"\r", b"not json", b"{", b"}", b"[]", b'"status"', b"42", b"null", b"true", b"{}",
    b"\xef\xbb\xbf{\"cmd\": \"ping\"}", b'{"cmd": "ping"}\r', b'{"cmd": "ping", "cmd": "status"}',
    b"\xff\xfe\xfd", b'{"cmd": "\xc3\x28"}', b'{"cmd": "ping"}\x00', b"\x00" * 10, b"{" * DEEP,
    b'{"cmd": "ping"} {"cmd": "ping"}', b'{"cmd": "ping"}garbage', b"\\u0000",
]  # fmt: skip


@st.composite
def frames(draw: st.DrawFn, paths: list[str]) -> Frame:
    """One well-framed request (valid or not), possibly several lines in one write or one line
    in pieces."""
    kind = draw(st.integers(0, 9))
    if kind <= 5:
        return line_frame(dump(draw(request_obj(paths))).encode("utf-8", "surrogatepass"))
    if kind == 6:
        return line_frame(draw(st.sampled_from(NON_JSON) | st.binary(max_size=200)))
    if kind == 7:  # a request cut short, then the newline
        full = dump(draw(request_obj(paths))).encode("utf-8", "surrogatepass")
        return line_frame(full[: draw(st.integers(0, max(len(full) - 1, 0)))])
    if kind == 8:  # several requests in one write: each answered, in order
        lines = draw(st.lists(request_obj(paths), min_size=2, max_size=4))
        data = b"".join(dump(m).encode("utf-8", "surrogatepass").replace(b"\n", b" ") + b"\n" for m in lines)
        payloads = tuple(data.split(b"\n")[:-1])
        return Frame("line", payloads, (data,)) if max(map(len, payloads)) <= MAX_LINE else line_frame(b"{}")
    f = line_frame(dump(draw(request_obj(paths))).encode("utf-8", "surrogatepass"))
    if f.kind != "line":
        return f
    cuts = sorted(draw(st.lists(st.integers(0, len(f.data)), max_size=4)))
    pieces = [f.data[i:j] for i, j in zip([0, *cuts], [*cuts, len(f.data)], strict=True)]
    return Frame("split", f.payloads, tuple(p for p in pieces if p))


def terminal_frames() -> st.SearchStrategy[Frame]:
    """The last step of a connection: an oversized line, or a line that never ends."""
    oversized = st.builds(
        lambda n, head: Frame("oversized", (head + b"a" * n,), (head + b"a" * n + b"\n",)),
        st.integers(MAX_LINE + 1, 3 * MAX_LINE),
        st.sampled_from([b"", b'{"cmd": "status", "args": {"x": "', b"[" * 100]),
    )
    partial = st.sampled_from(NON_JSON[1:]) | st.binary(min_size=1).map(
        lambda b: b.replace(b"\n", b"") or b"{"
    )
    truncated = partial.map(lambda b: Frame("truncated", (b,), (b,)))
    return oversized | truncated


def connections(paths: list[str]) -> st.SearchStrategy[list[Frame]]:
    """What one client does on one connection: 1-4 requests, then maybe a framing fault."""
    body = st.lists(frames(paths), min_size=1, max_size=4)
    return st.tuples(body, st.lists(terminal_frames(), max_size=1)).map(lambda t: [*t[0], *t[1]])


# ---- missions and configs ------------------------------------------------------------------

missions = mission_text.missions
configs = toml_text.configs
