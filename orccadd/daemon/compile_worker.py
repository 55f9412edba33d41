"""`python -m orccadd.daemon.compile_worker MISSION OUT`: compile and verify a mission in a
process of its own and pickle `(automaton, report)` — or the error, in words — into OUT.

The real-time process starts it for `load`: parsing, compiling and verifying are long Python
computations that, in the real-time process, would take the interpreter lock from the control
thread at every one of its system calls (measured: ticks of 2-3 ms instead of 0.3 ms on a
CANopen arm for as long as a load lasted).
"""

from __future__ import annotations

import pickle
import sys
from pathlib import Path

from orccadd.daemon.mission import compile_and_verify
from orccadd.errors import OrccaddError


def main(argv: list[str] | None = None) -> int:
    mission, out = argv if argv is not None else sys.argv[1:]
    try:
        result: object = compile_and_verify(mission)
        code = 0
    except OrccaddError as e:
        result, code = str(e), 1
    Path(out).write_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    return code


if __name__ == "__main__":
    raise SystemExit(main())
