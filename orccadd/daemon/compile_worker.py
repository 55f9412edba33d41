"""`python -m orccadd.daemon.compile_worker --fd N --name PATH [--task-dir DIR ...] OUT`: compile
and verify the mission read from descriptor N (opened and checked by the real-time process: see
`orccadd.confine`; PATH is its real path, for messages and for the task files it names) and
pickle `(automaton, report, task specs)` — or the error, in words — into OUT. Task files are read
from the `--task-dir` directories only, each by a checked descriptor.

With `--cache-dir`, a mission compiled and verified before (same text, task files and compiler:
`compile_cache`) is answered from there, and OUT.cached says so; only then is the compiler not
imported (half a second of this process's start). What it compiles it keeps there.

The real-time process starts it for `load`: parsing, compiling and verifying are long Python
computations that, in the real-time process, would take the interpreter lock from the control
thread at every one of its system calls (measured: ticks of 2-3 ms instead of 0.3 ms on a
CANopen arm for as long as a load lasted).
"""

from __future__ import annotations

import argparse
import os
import pickle
import resource
import sys
from pathlib import Path

from orccadd.config.robot import MAX_TOML_BYTES
from orccadd.confine import Confinement, read_fd
from orccadd.daemon.compile_cache import CompileCache
from orccadd.errors import MissionError, OrccaddError

MAX_MISSION_CHARS = 1_000_000  # orccadd.automaton.language.parser's (tests/daemon/test_compile_cache.py)
MAX_MISSION_BYTES = 4 * MAX_MISSION_CHARS  # UTF-8: at most 4 bytes a character
RESERVE_BYTES = 16 << 20


def _address_space_bytes() -> int:
    """This process's address space now (VmSize), in bytes."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 0


def read_mission(fd: int, name: str) -> bytes:
    data = read_fd(fd, MAX_MISSION_BYTES)
    if data is None:
        raise MissionError(name, 0, 0, f"larger than {MAX_MISSION_BYTES} bytes: not a mission")
    return data


def decode_mission(data: bytes, name: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise MissionError(name, 1, 1, f"the mission file is not UTF-8 text ({e.reason})") from None


def open_cache(directory: str) -> CompileCache | None:
    if not directory:
        return None
    cache = CompileCache(Path(directory))
    if why := cache.usable():
        print(f"orccadd: compile cache off: {why}", file=sys.stderr)
        return None
    return cache


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="orccadd.daemon.compile_worker")
    ap.add_argument("--fd", type=int, required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--task-dir", action="append", default=[])
    ap.add_argument("--memory-mb", type=int, default=0, help="address-space limit (0: none)")
    ap.add_argument("--cache-dir", default="", help="missions compiled before (compile_cache)")
    ap.add_argument("out")
    args = ap.parse_args(argv)
    confinement = Confinement(args.task_dir, "task file", "daemon.task_dirs, daemon.mission_dirs")
    cache = open_cache(args.cache_dir)
    try:
        data = read_mission(args.fd, args.name)
    except OrccaddError as e:
        return answer(args.out, str(e), 1)
    finally:
        os.close(args.fd)
    key = cache.key(args.name, data, args.task_dir) if cache is not None else ""
    if cache is not None:
        found = cache.lookup(key, lambda path: confinement.read(path, MAX_TOML_BYTES)[0])
        if found is not None:
            Path(f"{args.out}.cached").touch()
            Path(args.out).write_bytes(found)
            return 0
    from orccadd.daemon.mission import compile_and_verify  # the compiler: only when it compiles
    from orccadd.mission import TaskFiles

    files = TaskFiles(confinement)
    reserve = bytearray(RESERVE_BYTES)  # freed to write the answer should memory run out
    if args.memory_mb:  # on top of what the process holds once started (Python, numpy, Pinocchio)
        limit = _address_space_bytes() + (args.memory_mb << 20)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    try:
        automaton, report = compile_and_verify(args.name, decode_mission(data, args.name), files)
    except OrccaddError as e:
        return answer(args.out, str(e), 1)
    except MemoryError:
        del reserve
        files.specs.clear()  # what it holds goes: room to write the answer
        why = (
            f"{args.name}: the compiler needed more than {args.memory_mb} MB (daemon.load_memory_mb): "
            "too large a mission for this daemon's limit; `orccadctl check` shows how far it gets"
        )
        return answer(args.out, why, 1)
    pickled = pickle.dumps((automaton, report, files.specs), protocol=pickle.HIGHEST_PROTOCOL)
    Path(args.out).write_bytes(pickled)
    if cache is not None:
        cache.store(key, files.digests, pickled)
    return 0


def answer(out: str, result: object, code: int) -> int:
    """Write `result` (the error, in words) to `out`; `code` back."""
    Path(out).write_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    return code


if __name__ == "__main__":
    raise SystemExit(main())
