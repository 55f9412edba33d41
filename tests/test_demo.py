"""`make demo`'s recovery path: a motion stopped by T3 Overrun is retried after the safe stop."""

from __future__ import annotations

import subprocess
import sys

from tests.conftest import ROOT


def test_demo_recovers_from_overrun_faults() -> None:
    # overrun limit 1 without SCHED_FIFO: overruns are certain on a shared VM, the demo must cope
    r = subprocess.run(
        [sys.executable, "-m", "orccadd.demo", "--priority", "0", "--overrun-limit", "1", "--retries", "50"],
        capture_output=True, text=True, timeout=110, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.count(": done in") == 3
