"""Deployments: missions sent from a workstation (`orccadctl deploy`), stored by content.

A deployment is a mission's text and every task file it names (`from "..."`), as the client read
them. The daemon checks it exactly as `load` checks a file (the same compiler process, against
its own robot config), and only then stores it, in a directory of its own:

    <deploy_dir>/<hash>/<name>.mission        the mission, its `from "..."` rewritten to
    <deploy_dir>/<hash>/tasks/<file>           the task files, flat (no path of the client's
    <deploy_dir>/<hash>/deployment.json         is ever used on this side), and the record:
                                               name, hash, who deployed it and when, each file's
                                               sha256

The hash is the sha256 of the mission's text and its task files (name and content), so the same
content deployed twice is one deployment. `load NAME` (the newest deployment of that name) or
`load HASH` (at least 8 of its hex digits) loads one; `describe` names the loaded mission's hash.
Limits: `MAX_FILES` task files, what a request line carries (orccadd/wire/commands.py
`MAX_LINE`), `daemon.deployments_kept` deployments (the oldest pruned).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import stat
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from orccadd.config.station import StationConfig
from orccadd.daemon.replies import CommandError

MAX_FILES = 64
NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")
FROM_RE = re.compile(r'\bfrom\s+"([^"\n]*)"')  # a task's file in a mission: `task T on R from "F"`
HASH_RE = re.compile(r"^[0-9a-f]{8,64}$")
RECORD = "deployment.json"


@dataclass(frozen=True)
class Record:
    """What is kept of a deployment beside its files."""

    name: str
    hash: str
    by: str
    at_utc: str
    files: dict[str, str]  # the client's name of each file (the mission: NAME.mission) -> sha256


def default_dir() -> Path:
    """Where deployments go without `daemon.deploy_dir`: systemd's StateDirectory, else
    $XDG_STATE_HOME/orccadd, else ~/.local/state/orccadd (each `/deployments`)."""
    if state := os.environ.get("STATE_DIRECTORY", "").split(":")[0]:
        return Path(state) / "deployments"
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "orccadd" / "deployments"


def deploy_dir(cfg: StationConfig) -> Path:
    """This daemon's deployments' directory (created 0700, owned by it and by it alone)."""
    d = cfg.daemon.deploy_dir
    path = cfg.resolve(d) if d else default_dir()
    try:
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = os.stat(path, follow_symlinks=False)
    except OSError as e:
        raise CommandError(f"deployments: {path}: {e.strerror or e} (daemon.deploy_dir)") from None
    others_write = st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid() or others_write:
        raise CommandError(
            f"deployments: {path} must be a directory of this daemon's user that no one else may "
            "write to (daemon.deploy_dir)"
        )
    return path


def content_hash(name: str, mission: str, files: dict[str, str]) -> str:
    """The sha256 of the mission (its name and text) and its task files (the names it uses and
    their content), each part length-prefixed."""
    h = hashlib.sha256(b"orccadd deployment 1\n")
    for part in (name, mission, *(x for k in sorted(files) for x in (k, files[k]))):
        data = part.encode()
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


def referenced(mission: str) -> list[str]:
    """The task files a mission names (`from "..."`), in order, once each."""
    return list(dict.fromkeys(FROM_RE.findall(mission)))


@dataclass(frozen=True)
class Staged:
    """A deployment written to a staging directory, to be compiled before it is committed."""

    path: Path
    name: str
    hash: str
    mission: Path  # the mission file, as the compiler is to read it
    files: dict[str, str]  # sha256 of each file, by the client's name

    @property
    def tasks(self) -> Path:
        return self.path / "tasks"


def stage(root: Path, name: str, mission: str, files: dict[str, str]) -> Staged | Path:
    """Check the deployment's form and write it to a staging directory under `root`; or the
    path of the same content deployed before. `CommandError` naming what is wrong."""
    if not NAME_RE.match(name):
        raise CommandError(
            f"deploy: name {name!r} must be 1-64 letters, digits, '_', '-' or '.' (a file's stem)"
        )
    if len(files) > MAX_FILES:
        raise CommandError(f"deploy: {len(files)} task files: at most {MAX_FILES}")
    wanted = referenced(mission)
    missing = [f for f in wanted if f not in files]
    if missing:
        raise CommandError(
            f"deploy: the mission names {', '.join(missing)}, which the deployment does not carry"
        )
    extra = sorted(set(files) - set(wanted))
    if extra:
        raise CommandError(f'deploy: {", ".join(extra)}: not named by the mission (`from "..."`)')
    h = content_hash(name, mission, files)
    final = root / h
    if (final / RECORD).is_file():
        return final
    sums = {f"{name}.mission": _sha(mission)}
    flat: dict[str, str] = {}
    for ref in wanted:
        base = os.path.basename(ref.replace("\\", "/")) or "task.toml"
        stored = f"{_sha(files[ref])[:12]}-{re.sub(r'[^A-Za-z0-9_.-]', '_', base)[:80]}"
        flat[ref] = stored
        sums[ref] = _sha(files[ref])
    text = FROM_RE.sub(lambda m: f'from "tasks/{flat[m.group(1)]}"', mission)
    staging = root / f".staging-{h[:16]}-{os.getpid()}-{time.monotonic_ns()}"
    (staging / "tasks").mkdir(mode=0o700, parents=True)
    for ref, stored in flat.items():
        (staging / "tasks" / stored).write_text(files[ref])
    mission_path = staging / f"{name}.mission"
    mission_path.write_text(text)
    return Staged(staging, name, h, mission_path, sums)


def commit(root: Path, staged: Staged, by: str, keep: int) -> Record:
    """The staged deployment, verified, moved to its place with its record; the oldest beyond
    `keep` pruned."""
    at = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    record = Record(staged.name, staged.hash, by or "unknown", at, staged.files)
    (staged.path / RECORD).write_text(json.dumps(asdict(record), indent=1) + "\n")
    final = root / staged.hash
    try:
        os.rename(staged.path, final)
    except OSError:  # deployed meanwhile by another request: the same content
        shutil.rmtree(staged.path, ignore_errors=True)
    prune(root, keep)
    return record


def discard(staged: Staged) -> None:
    shutil.rmtree(staged.path, ignore_errors=True)


def prune(root: Path, keep: int) -> None:
    """The deployments beyond the `keep` newest removed (and staging left by a crash)."""
    entries = sorted(
        (p for p in root.iterdir() if HASH_RE.match(p.name) and (p / RECORD).is_file()),
        key=lambda p: (p / RECORD).stat().st_mtime,
        reverse=True,
    )
    for old in entries[keep:]:
        shutil.rmtree(old, ignore_errors=True)
    hour_ago = time.time() - 3600
    for p in root.glob(".staging-*"):
        if p.stat().st_mtime < hour_ago:
            shutil.rmtree(p, ignore_errors=True)


def read_record(path: Path) -> Record:
    return Record(**json.loads((path / RECORD).read_text()))


def find(root: Path, ref: str) -> tuple[Path, Record] | None:
    """The deployment `ref` names: a hash (8 or more of its hex digits) or a name (the newest of
    that name); None if none does."""
    if not root.is_dir():
        return None
    found = []
    for p in root.iterdir():
        if not HASH_RE.match(p.name) or not (p / RECORD).is_file():
            continue
        try:
            rec = read_record(p)
        except (OSError, ValueError, TypeError):
            continue
        if (HASH_RE.match(ref) and p.name.startswith(ref)) or rec.name == ref:
            found.append((rec.at_utc, p, rec))
    if not found:
        return None
    _, path, rec = max(found, key=lambda x: (x[0], x[1].stat().st_mtime))
    return path, rec


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()
