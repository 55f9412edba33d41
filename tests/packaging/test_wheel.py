"""The wheel holds what the repository holds: a file lying untracked in a checkout's configs/ (a
robot config of one's own, a scratch mission) is not shipped."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.conftest import ROOT


@pytest.mark.skipif(
    shutil.which("git") is None or not (ROOT / ".git").exists(), reason="needs the git checkout"
)
def test_the_wheel_ships_tracked_files_only(tmp_path: Path) -> None:
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True, timeout=120)
    (clone / "configs/robots/my-own-arm.toml").write_text("name = 'mine'\n")  # untracked
    env = {**os.environ, "PYTHON": sys.executable}
    build = [str(clone / "packaging/build-wheel.sh"), str(tmp_path / "dist")]
    out = subprocess.run(build, capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    [wheel] = list((tmp_path / "dist").glob("orccadd-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    robots = [n for n in names if "/share/orccadd/configs/robots/" in n]
    assert any(n.endswith("/sim-ur5e.toml") for n in robots), robots  # the shipped ones are there
    assert not any("my-own-arm" in n for n in names)
