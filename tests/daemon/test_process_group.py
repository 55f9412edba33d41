"""A signal to orccadd's whole process group (Ctrl-C in a shell, `kill %1`, systemd stopping the
service): the real-time process alone receives it, safe-stops the arm through its children, then
ends them. Exit status 0, the stop confirmed, no process left."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from tests.daemon.conftest import ROOT, robot_config, start_daemon_with

DEMO = str(ROOT / "configs/missions/demo.mission")


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_to_the_whole_group_mid_motion_ends_in_a_confirmed_safe_stop(
    tmp_path: Path, sig: signal.Signals
) -> None:
    d = start_daemon_with(tmp_path, robot_config(tmp_path), own_group=True)
    try:
        cmdd_pid = int(d.call("ping")["pid"])  # type: ignore[index]
        plant_pid = int(d.status()["helper_pid"])  # type: ignore[arg-type]
        assert alive(cmdd_pid) and alive(plant_pid)
        d.call("load", path=DEMO)
        d.call("start")
        d.wait(lambda s: max(abs(j["dq_rad_s"]) for j in s["joints"]) > 0.1)  # type: ignore[union-attr]
        os.killpg(d.proc.pid, sig)  # the group: what the shell and systemd's group kill do
        code = d.proc.wait(timeout=30)
        log = d.log.read_text()
        assert code == 0, log
        assert "safe stop first" in log and "arm at rest, hardware released" in log, log
        deadline = time.monotonic() + 10
        while (alive(cmdd_pid) or alive(plant_pid)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not alive(cmdd_pid) and not alive(plant_pid)
    finally:
        d.stop()
