"""A daemon's logs brought back to the console: `logs` lists them, `fetch` reads one in chunks.

Both are the command daemon's (the read role suffices), over the socket or the cell, and never
block its event loop on the disk: a chunk is read, and a file's sha256 computed, in a worker
thread. A chunk is at most `CHUNK_BYTES` (base64 in a reply line well under its limit); the
client asks for them in turn and checks the whole file against the sha256 that the last chunk's
reply carries. Only files of the log directory that are logs or their MCAP parts (the names
`csvlog.LOG_NAME`, `PART_NAME` allow), never the one being written, never through a link.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import json
import os
import re
import stat
import time
from pathlib import Path
from typing import Any

from orccadd.cmdd.csvlog import LOG_NAME, PART_NAME

CHUNK_BYTES = 32 * 1024
RESULTS = ("success", "failed", "aborted", "safe")  # a run's end, as the log's events name it
TAIL_BYTES = 256 * 1024  # how much of a log's end is read for its mission's result


def list_logs(log_dir: Path, writing: str = "") -> list[dict[str, Any]]:
    """Each log of `log_dir`: its CSV's name and size, its MCAP parts, when it started, the
    mission and its result as its events say (what the last 256 KiB of the CSV shows)."""
    if not log_dir.is_dir():
        return []
    out = []
    names = sorted(os.listdir(log_dir))
    for name in names:
        if not LOG_NAME.fullmatch(name):
            continue
        path = log_dir / name
        try:
            st = os.stat(path, follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            continue
        stem = name[: -len(".csv")]
        parts = [n for n in names if PART_NAME.fullmatch(n) and is_part_of(stem, n)]
        sizes = sum(os.stat(log_dir / p).st_size for p in parts if (log_dir / p).is_file())
        out.append(
            {
                "name": name,
                "mcap": parts,
                "size": st.st_size + sizes,
                "modified_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(st.st_mtime)),
                "writing": name == writing,
                **_header_and_end(path, st.st_size),
            }
        )
    return out


def _header_and_end(path: Path, size: int) -> dict[str, Any]:
    """The log's start and the mission loaded then (its header), and how the last run in it
    ended (its events, from the end of the file: an instant whose actions end the mission)."""
    info: dict[str, Any] = {"start_utc": "", "mission": "", "deployment": "", "result": ""}
    try:
        with path.open("rb") as f:
            first = f.readline(64 * 1024).decode(errors="replace")
            if first.startswith("# orccadd log "):
                meta = json.loads(first[len("# orccadd log ") :])
                info["start_utc"] = meta.get("start_utc", "")
                info["mission"] = meta.get("mission", "")
                info["deployment"] = meta.get("mission_deployment", "")
            f.seek(max(0, size - TAIL_BYTES))
            tail = f.read(TAIL_BYTES).decode(errors="replace")
    except (OSError, ValueError):
        return info
    for line in tail.splitlines():
        cells = line.split(",", 5) if line.startswith("# event,") else []
        if len(cells) > 5 and cells[3] == "instant" and "->" in cells[5]:
            actions = cells[5].split("->", 1)[1].split("(state")[0].split()
            for r in RESULTS:
                if r in actions:
                    info["result"] = r
    return info


def is_part_of(stem: str, name: str) -> bool:
    """Whether `name` is an MCAP part of the log `<stem>.csv`: `<stem>.mcap`, `<stem>-N.mcap`."""
    return re.fullmatch(re.escape(stem) + r"(-\d+)?\.mcap", name) is not None


async def read_chunk(log_dir: Path, name: str, offset: int, length: int, writing: str) -> dict[str, Any]:
    """`length` bytes (at most CHUNK_BYTES) of log file `name` from `offset`, base64; with the
    file's size, and its sha256 when this chunk reaches its end. `ValueError` saying why not."""
    if not (LOG_NAME.fullmatch(name) or PART_NAME.fullmatch(name)):
        raise ValueError(f"fetch: {name[:120]!r} is not a log of this daemon (`orccadctl logs` lists them)")
    if writing and (name == writing or is_part_of(writing[: -len(".csv")], name)):
        raise ValueError(f"fetch: {name} is being written: `orccadctl log stop` first")
    if not offset >= 0 or not 1 <= length <= CHUNK_BYTES:
        raise ValueError(
            f"fetch: offset (={offset}) must be >= 0 and length (={length}) in [1, {CHUNK_BYTES}]"
        )
    return await asyncio.to_thread(_read, log_dir, name, offset, length)


def _read(log_dir: Path, name: str, offset: int, length: int) -> dict[str, Any]:
    try:
        dir_fd = os.open(log_dir, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC, dir_fd=dir_fd)
        finally:
            os.close(dir_fd)
    except FileNotFoundError:
        raise ValueError(f"fetch: no log {name} (`orccadctl logs` lists them)") from None
    except OSError as e:
        raise ValueError(f"fetch: {name}: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"fetch: {name} is not a regular file")
        data = os.pread(fd, length, offset)
        reply: dict[str, Any] = {
            "name": name,
            "size": st.st_size,
            "offset": offset,
            "data": base64.b64encode(data).decode(),
        }
        if offset + len(data) >= st.st_size:
            h = hashlib.sha256()
            pos = 0
            while chunk := os.pread(fd, 1 << 20, pos):
                h.update(chunk)
                pos += len(chunk)
            reply["sha256"] = h.hexdigest()
        return reply
    finally:
        os.close(fd)
