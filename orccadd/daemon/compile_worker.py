"""`python -m orccadd.daemon.compile_worker --fd N --name PATH [--task-dir DIR ...] OUT`: compile
and verify the mission read from descriptor N (opened and checked by the real-time process: see
`orccadd.confine`; PATH is its real path, for messages and for the task files it names) and
pickle `(automaton, report, task specs)` — or the error, in words — into OUT. Task files are read
from the `--task-dir` directories only, each by a checked descriptor.

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
from pathlib import Path

from orccadd.automaton.parser import MAX_MISSION_CHARS
from orccadd.confine import Confinement, read_fd
from orccadd.daemon.mission import compile_and_verify
from orccadd.errors import MissionError, OrccaddError
from orccadd.mission import TaskFiles

MAX_MISSION_BYTES = 4 * MAX_MISSION_CHARS  # UTF-8: at most 4 bytes a character
RESERVE_BYTES = 16 << 20


def _address_space_bytes() -> int:
    """This process's address space now (VmSize), in bytes."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 0


def read_mission(fd: int, name: str) -> str:
    data = read_fd(fd, MAX_MISSION_BYTES)
    if data is None:
        raise MissionError(name, 0, 0, f"larger than {MAX_MISSION_BYTES} bytes: not a mission")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise MissionError(name, 1, 1, f"the mission file is not UTF-8 text ({e.reason})") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="orccadd.daemon.compile_worker")
    ap.add_argument("--fd", type=int, required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--task-dir", action="append", default=[])
    ap.add_argument("--memory-mb", type=int, default=0, help="address-space limit (0: none)")
    ap.add_argument("out")
    args = ap.parse_args(argv)
    reserve = bytearray(RESERVE_BYTES)  # freed to write the answer should memory run out
    if args.memory_mb:  # on top of what the process holds once started (Python, numpy, Pinocchio)
        limit = _address_space_bytes() + (args.memory_mb << 20)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    files = TaskFiles(Confinement(args.task_dir, "task file", "daemon.task_dirs, daemon.mission_dirs"))
    try:
        text = read_mission(args.fd, args.name)
        os.close(args.fd)
        automaton, report = compile_and_verify(args.name, text, files)
        result: object = (automaton, report, files.specs)
        code = 0
    except OrccaddError as e:
        result, code = str(e), 1
    except MemoryError:
        del reserve
        files.specs.clear()  # what it holds goes: room to write the answer
        result = (
            f"{args.name}: the compiler needed more than {args.memory_mb} MB (daemon.load_memory_mb): "
            "too large a mission for this daemon's limit; `orccadctl check` shows how far it gets"
        )
        code = 1
    Path(args.out).write_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    return code


if __name__ == "__main__":
    raise SystemExit(main())
