"""`log stop -o FILE`: the copy is made with the caller's rights, from and to no link, never
wider than the daemon's file; with `--robot`, nothing is copied from paths another PC names."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from orccadd.ctl.online import copy_to


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def test_a_private_log_stays_private_and_a_readable_one_readable(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        for bits in (0o600, 0o640, 0o644):
            src = tmp_path / f"log-{bits:o}.csv"
            src.write_text("t_s,q0\n0,1\n")
            src.chmod(bits)
            dest = tmp_path / f"copy-{bits:o}.csv"
            copy_to(src, dest)
            assert dest.read_text() == "t_s,q0\n0,1\n" and _mode(dest) == bits, oct(_mode(dest))
    finally:
        os.umask(old)


def test_no_link_is_followed_at_either_end(tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_text("root only")
    secret.chmod(0o600)
    link = tmp_path / "log.csv"
    link.symlink_to(secret)
    with pytest.raises(OSError):
        copy_to(link, tmp_path / "out.csv")
    assert not (tmp_path / "out.csv").exists()
    src = tmp_path / "real.csv"
    src.write_text("x")
    planted = tmp_path / "planted.csv"
    planted.symlink_to(secret)
    with pytest.raises(OSError):
        copy_to(src, planted)
    assert secret.read_text() == "root only"
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="not a regular file"):
        copy_to(fifo, tmp_path / "out.csv")  # refused without blocking


def test_log_stop_o_with_robot_is_refused_before_anything_is_sent(tmp_path: Path) -> None:
    dest = tmp_path / "run.csv"
    r = subprocess.run(
        [sys.executable, "-m", "orccadd.cli", "--cell", str(tmp_path / "none.toml"), "--robot", "arm-b",
         "log", "stop", "-o", str(dest)],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert r.returncode == 2 and "the log is on arm-b's PC" in r.stderr, r.stderr
    assert not dest.exists()
