"""Where `make test`'s time goes, per test: a pytest plugin, from the checkout's root:

    .venv/bin/python -m pytest -p tools.pytest_cost

For each test: its wall time, its CPU time (this process and the children it reaped) and whether
a SCHED_FIFO or SCHED_RR thread ran in its process tree while it ran (sampled every 50 ms: a
daemon's loop, a plant, a device simulator, a loop in the test's own process). One JSON line per
test in $ORCCADD_TEST_COST (default: test-cost-<worker>.jsonl in the current directory); then,
for instance, per file:

    python -m tools.pytest_cost test-cost-*.jsonl

docs/status.md ("The test suite") has what it measured. The sampler is a thread of this process:
a test that counts this process's allocations (tests/task/test_allocation.py) sees its own.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import pytest

REALTIME_POLICIES = (1, 2)  # SCHED_FIFO, SCHED_RR


def _cpu_s() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _tree(pid: int) -> list[int]:
    """`pid` and every process below it."""
    out = [pid]
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            try:
                kids = Path(f"/proc/{pid}/task/{tid}/children").read_text().split()
            except OSError:
                continue
            for kid in kids:
                out += _tree(int(kid))
    except OSError:
        pass
    return out


def _realtime_thread_in(pids: list[int]) -> bool:
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            try:
                stat = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if len(fields) > 38 and int(fields[38]) in REALTIME_POLICIES:
                return True
    return False


class _Sampler:
    def __init__(self) -> None:
        self.seen = False
        threading.Thread(target=self._run, name="pytest-cost", daemon=True).start()

    def _run(self) -> None:
        me = os.getpid()
        while True:
            time.sleep(0.05)
            if not self.seen and _realtime_thread_in(_tree(me)):
                self.seen = True


_sampler: _Sampler | None = None
_out: IO[str] | None = None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    global _sampler, _out
    if _sampler is None:
        _sampler = _Sampler()
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        _out = open(os.environ.get("ORCCADD_TEST_COST", f"test-cost-{worker}.jsonl"), "a")  # noqa: SIM115
    assert _out is not None
    _sampler.seen = False
    cpu0, t0 = _cpu_s(), time.monotonic()
    yield
    row = {
        "id": item.nodeid,
        "wall_s": time.monotonic() - t0,
        "cpu_s": _cpu_s() - cpu0,
        "realtime": _sampler.seen,
    }
    _out.write(json.dumps(row) + "\n")
    _out.flush()


def main(paths: list[str]) -> int:
    """Per file: wall and CPU seconds, tests, tests that ran a real-time thread; then the totals."""
    files: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0, 0])
    for path in paths:
        for line in Path(path).read_text().splitlines():
            row = json.loads(line)
            f = files[row["id"].split("::")[0]]
            f[0] += row["wall_s"]
            f[1] += row["cpu_s"]
            f[2] += 1
            f[3] += bool(row["realtime"])
    print(f"{'wall s':>8} {'CPU s':>8} {'tests':>6} {'real-time':>9}  file")
    for name, (wall, cpu, n, rt) in sorted(files.items(), key=lambda kv: -kv[1][0]):
        print(f"{wall:8.1f} {cpu:8.1f} {n:6d} {rt:9d}  {name}")
    wall, cpu, n, rt = (sum(f[i] for f in files.values()) for i in range(4))
    print(f"{wall:8.1f} {cpu:8.1f} {int(n):6d} {int(rt):9d}  (all)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
