"""Robot config texts mutated at the TOML-value level.

A shipped config (configs/robots/*.toml, its relative paths made absolute) is read into a dict;
a mutation picks a key path and gives it a value of the wrong type, a number out of range, a
hostile path, a huge array, or deletes it, or adds an unknown key; `dumps` writes the dict back
as TOML. A last byte-level step may cut the file, insert garbage, or break its UTF-8.
"""

from __future__ import annotations

import copy
import datetime
import math
import re
import tomllib
from functools import cache
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from tests.conftest import ROOT, TESTDATA

SEEDS = sorted((ROOT / "configs" / "robots").glob("*.toml"))
KeyPath = tuple[str | int, ...]


@cache
def seed_dict(path: Path) -> dict[str, Any]:
    """A shipped config as a dict, its relative files made absolute (URDF, tasks, drive EDS)."""
    text = path.read_text()
    text = text.replace('"../', f'"{path.parent.parent}/')
    if TESTDATA is not None:
        text = text.replace('eds = "Elmo.dcf"', f'eds = "{TESTDATA}/eds/ros_canopen/Elmo.dcf"')
    return tomllib.loads(text)


# ---- writing TOML ----------------------------------------------------------------------------

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def _key(k: str) -> str:
    return k if _BARE.fullmatch(k) else _string(k)


def _string(s: str) -> str:
    out = []
    for ch in s:
        o = ord(ch)
        if ch in '"\\':
            out.append("\\" + ch)
        elif o < 0x20 or o == 0x7F:
            out.append(f"\\u{o:04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def value(v: Any) -> str:
    """One TOML value, inline."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, datetime.datetime | datetime.date | datetime.time):
        return v.isoformat()
    if isinstance(v, list):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(str(k))} = {value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no TOML for {type(v).__name__}")


def _is_tables(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(d: dict[str, Any]) -> str:
    """A TOML document of `d` (tables as [headers], lists of tables as [[headers]])."""
    out: list[str] = []
    _table(d, [], out, header="")
    return "\n".join(out) + "\n"


def _table(d: dict[str, Any], path: list[str], out: list[str], header: str) -> None:
    if header:
        out.append(header)
    for k, v in d.items():
        if not isinstance(v, dict) and not _is_tables(v):
            out.append(f"{_key(k)} = {value(v)}")
    for k, v in d.items():
        sub = [*path, _key(k)]
        if isinstance(v, dict):
            _table(v, sub, out, f"[{'.'.join(sub)}]")
        elif _is_tables(v):
            for item in v:
                _table(item, sub, out, f"[[{'.'.join(sub)}]]")


# ---- mutations -------------------------------------------------------------------------------


def key_paths(d: Any, prefix: KeyPath = ()) -> list[KeyPath]:
    """Every key path in `d` (tables and lists walked), the root excluded."""
    out: list[KeyPath] = []
    items = d.items() if isinstance(d, dict) else enumerate(d) if isinstance(d, list) else ()
    for k, v in items:
        p = (*prefix, k)
        out.append(p)
        out.extend(key_paths(v, p))
    return out


def _parent(d: Any, path: KeyPath) -> Any:
    for k in path[:-1]:
        d = d[k]
    return d


HOSTILE_STRINGS = [
    "", " ", "/etc/shadow", "/dev/null", "/", "/proc/self/status", "..", "../../../../etc/passwd",
    "example-robot-data:", "example-robot-data:../../../../etc/passwd", "x" * 300, "\x00", "a\x00b",
    "é\u202e", "😀", "x" * 300 + "/a.urdf", "/etc", "sim", "sim_process", "canopen402", "nosuch", "arm",
    "C:\\urdf", "~/x.urdf",
]  # fmt: skip
HOSTILE_PATHS = [
    "", "/", "..", "/etc", "/etc/shadow", "/dev/null", "/proc/self/status", "../../../../etc/passwd",
    "x" * 300, "x" * 300 + "/a.urdf", "\x00", "a\x00b", "é\u202e",
    "example-robot-data:../../../../etc/passwd",
]  # fmt: skip
OUT_OF_RANGE = [
    0, -1, 1, 2**31, 2**63 - 1, -(2**63), 10**30, 0.0, -0.0, -1e-300, 1e-320, 1e308, -1e308,
    math.nan, math.inf, -math.inf, 0.5, 1e-9, 3.2, 1000.0,
]  # fmt: skip


def wrong_values() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.sampled_from(OUT_OF_RANGE),
        st.sampled_from(HOSTILE_STRINGS),
        st.booleans(),
        st.integers(),
        st.floats(),
        st.text(max_size=20),
        st.just(datetime.datetime(1979, 5, 27, 7, 32)),
        st.just(datetime.date(1979, 5, 27)),
        st.lists(st.floats() | st.integers(-5, 5), max_size=8),
        st.lists(st.text(max_size=5), max_size=3),
        st.just([]),
        st.just({}),
        st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
        st.integers(1000, 20_000).map(lambda n: [0.1] * n),  # a huge array
        st.just([[1.0, 2.0], [3.0]]),
    )


def value_at(d: Any, path: KeyPath) -> Any:
    return _parent(d, path)[path[-1]]


def with_value(d: dict[str, Any], path: KeyPath, v: Any) -> dict[str, Any]:
    """A copy of `d` with the value at `path` replaced."""
    out = copy.deepcopy(d)
    _parent(out, path)[path[-1]] = v
    return out


def is_file_name(v: Any) -> bool:
    return isinstance(v, str) and ("/" in v or v.endswith((".urdf", ".toml", ".dcf", ".eds")))


@st.composite
def mutated_dict(draw: st.DrawFn, d: dict[str, Any]) -> dict[str, Any]:
    """`d` with one value-level edit."""
    d = copy.deepcopy(d)
    paths = key_paths(d)
    if not paths:  # edited down to nothing (a short cell config: `name` and `[[resources]]`)
        return d
    op = draw(st.integers(0, 7))
    files = [p for p in paths if is_file_name(_parent(d, p)[p[-1]])]
    if op >= 6 and files:  # a file name made hostile: NUL, 300-byte names, system files, `..`
        path = draw(st.sampled_from(files))
        _parent(d, path)[path[-1]] = draw(st.sampled_from(HOSTILE_STRINGS) | st.text(max_size=8))
        return d
    path = draw(st.sampled_from(paths))
    parent = _parent(d, path)
    if op <= 2:  # a wrong or out-of-range value
        parent[path[-1]] = draw(wrong_values())
    elif op == 3:  # a key missing (or a list item)
        del parent[path[-1]]
    elif op == 4:  # an unknown key in a table
        table = parent[path[-1]] if isinstance(parent[path[-1]], dict) else parent
        if isinstance(table, dict):
            table[draw(st.sampled_from(["extra", "Name", "joints ", "source", "backend_settings"]))] = 1
        else:
            table.append(copy.deepcopy(table[-1]) if table else 0)  # one more list item
    elif isinstance(parent, list):  # the list item repeated or the list emptied
        if draw(st.booleans()):
            parent.extend(copy.deepcopy(parent[-1:]) * draw(st.integers(1, 40)))
        else:
            parent.clear()
    else:  # a table or array replaced by a scalar, or a scalar by a table
        parent[path[-1]] = (
            {} if not isinstance(parent[path[-1]], dict) else draw(st.sampled_from([1, "x", []]))
        )
    return d


@st.composite
def byte_edit(draw: st.DrawFn, data: bytes) -> bytes:
    """A last, byte-level edit, in one example of three."""
    op = draw(st.integers(0, 8))
    if op < 6 or not data:
        return data
    pos = draw(st.integers(0, len(data)))
    if op == 6:
        return data[:pos]
    if op == 7:
        junk = draw(
            st.sampled_from([b"\xff\xfe", b"\xc3\x28", b"\x00", b"[[", b"]", b"=", b"\n[joints]\n"])
            | st.binary()
        )
        return data[:pos] + junk + data[pos:]
    line_start = data.rfind(b"\n", 0, pos) + 1
    line_end = data.find(b"\n", pos)
    line = data[line_start : line_end if line_end >= 0 else len(data)]
    return data[:line_start] + line + b"\n" + data[line_start:]  # a duplicated line


@st.composite
def configs(draw: st.DrawFn) -> bytes:
    """A robot config file's bytes: a shipped one mutated 1-3 times, or garbage."""
    if draw(st.integers(0, 19)) == 0:
        return draw(st.binary(max_size=300))
    d = seed_dict(draw(st.sampled_from(SEEDS)))
    for _ in range(draw(st.integers(1, 3))):
        d = draw(mutated_dict(d))
    return draw(byte_edit(dumps(d).encode("utf-8", "surrogatepass")))
