"""A simulator started through `orccadd.simproc` dies with its parent: a test ended by
pytest-timeout's `os._exit` leaves no simulator running (at real-time priority) behind it."""

from __future__ import annotations

import importlib
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT

PARENT = """
import os, sys
sys.path.insert(0, {root!r})
from orccadd.vcan.process import HubProcess
hub = HubProcess()
print(hub.proc.pid, flush=True)
os._exit(0)
"""


def _running(pid: int) -> bool:
    """Alive and not a zombie (a dead child nobody reaped yet)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def test_a_child_dies_with_its_parent() -> None:
    out = subprocess.run(
        [sys.executable, "-c", PARENT.format(root=str(ROOT))], capture_output=True, text=True, timeout=60
    )
    pid = int(out.stdout.strip())
    deadline = time.monotonic() + 10
    while _running(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _running(pid)


@pytest.mark.parametrize("module", ["orccadd.drivesim", "orccadd.dxlsim", "orccadd.ursim", "orccadd.vcan"])
def test_a_simulators_usage_names_the_command_that_runs_it(
    module: str, capsys: pytest.CaptureFixture[str]
) -> None:
    main = importlib.import_module(f"{module}.__main__").main
    with pytest.raises(SystemExit):
        main(["--help"])
    assert capsys.readouterr().out.startswith(f"usage: python -m {module} ")


@pytest.mark.parametrize("module", ["plantsim", "drivesim", "dxlsim", "ursim", "vcan"])
def test_each_simulators_usage_names_the_command_that_runs_it(module: str) -> None:
    r = subprocess.run(
        [sys.executable, "-m", f"orccadd.{module}", "--help"], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0 and r.stdout.startswith(f"usage: python -m orccadd.{module} "), r.stdout[:200]
