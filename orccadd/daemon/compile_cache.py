"""Missions compiled and verified before, by content: `load` of a mission whose text, task files
and compiler are the same as at an earlier load gets that load's result without compiling again.

An entry is keyed by the compiler's code (every source file of this package, and the Python that
runs it), the mission's real path (its messages name it), its text and the task directories it
may read from. It records each task file the compile read and the SHA-256 of what it read: a hit
reads those files again (through the same confinement) and must find each unchanged, as ccache's
manifests do. What it holds is the compile worker's answer as written: the real-time process
reads it as it reads a fresh one.

The directory holds pickles that the daemon loads: it is used only if this user owns it and no
one else may write to it (created 0700 where absent); otherwise the cache is off, said once on
standard error. Entries are written whole (a temporary file renamed), so that two daemons sharing
a directory never read half of one; a damaged or foreign entry is a miss.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]
FORMAT = b"orccadd-compile-cache 1\n"
MAX_ENTRIES = 256  # beyond, the least recently stored go


def code_id() -> str:
    """SHA-256 of the code a compile runs: the Python version and every source file of orccadd
    (its path and content), so that an edited or upgraded compiler never meets an old entry."""
    h = hashlib.sha256(sys.version.encode())
    for path in sorted(PACKAGE.rglob("*.py")):
        h.update(str(path.relative_to(PACKAGE)).encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def default_dir() -> Path:
    """missions/ in systemd's `CacheDirectory=` ($CACHE_DIRECTORY), else in
    $XDG_CACHE_HOME/orccadd, else in ~/.cache/orccadd."""
    if d := os.environ.get("CACHE_DIRECTORY", "").split(":")[0]:
        return Path(d) / "missions"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "orccadd" / "missions"


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class CompileCache:
    def __init__(self, directory: Path) -> None:
        self.dir = directory
        self._code_id = ""

    def usable(self) -> str:
        """'' if the directory may hold this daemon's entries (created 0700 if absent), else why
        not."""
        try:
            self.dir.mkdir(mode=0o700, parents=True, exist_ok=True)
            st = os.stat(self.dir, follow_symlinks=False)
        except OSError as e:
            return f"{self.dir}: {e.strerror or e}"
        if not stat.S_ISDIR(st.st_mode):
            return f"{self.dir}: not a directory"
        if st.st_uid != os.geteuid():
            return f"{self.dir}: owned by uid {st.st_uid}, not by this user ({os.geteuid()})"
        if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
            return f"{self.dir}: others may write to it (mode {stat.S_IMODE(st.st_mode):o})"
        return ""

    def key(self, name: str, text: bytes, task_dirs: Sequence[str]) -> str:
        if not self._code_id:
            self._code_id = code_id()
        h = hashlib.sha256(FORMAT + self._code_id.encode())
        for part in (name.encode(), text, "\0".join(task_dirs).encode()):
            h.update(len(part).to_bytes(8, "little") + part)
        return h.hexdigest()

    def lookup(self, key: str, read: Callable[[str], bytes]) -> bytes | None:
        """The answer stored under `key` if each task file it records still reads (`read(path)`,
        any `Exception`: a miss) as it did; None otherwise."""
        try:
            blob = (self.dir / key).read_bytes()
        except OSError:
            return None
        if not blob.startswith(FORMAT):
            return None
        header, sep, answer = blob[len(FORMAT) :].partition(b"\n")
        try:
            files = json.loads(header)
            for path, sha in files.items():
                if digest(read(path)) != sha:
                    return None
        except Exception:  # a damaged entry, a file gone or now refused: compile it again
            return None
        return answer if sep else None

    def store(self, key: str, files: dict[str, str], answer: bytes) -> None:
        """Keep `answer` (the worker's pickled result) under `key` with the task files read
        (path -> SHA-256); a failure to write is no error (the next load compiles again)."""
        tmp = self.dir / f".{key}.{os.getpid()}"
        try:
            with open(tmp, "xb") as f:
                f.write(FORMAT + json.dumps(files, sort_keys=True).encode() + b"\n" + answer)
            os.replace(tmp, self.dir / key)
        except OSError:
            tmp.unlink(missing_ok=True)
            return
        self._prune()

    def _prune(self) -> None:
        try:
            entries = [(e.stat().st_mtime_ns, e) for e in os.scandir(self.dir) if not e.name.startswith(".")]
        except OSError:
            return
        for _, e in sorted(entries, key=lambda x: x[0])[: max(0, len(entries) - MAX_ENTRIES)]:
            Path(e.path).unlink(missing_ok=True)
