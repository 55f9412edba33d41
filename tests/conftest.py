"""Shared fixtures: shipped configs, variants of them written to a temporary folder."""

from __future__ import annotations

import compileall
import ctypes
import os
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
UR5E = ROOT / "configs" / "robots" / "sim-ur5e.toml"
PANDA = ROOT / "configs" / "robots" / "sim-panda.toml"
MOVE_TASK = ROOT / "configs" / "tasks" / "move_joints.toml"
URDF_DIR = ROOT / "configs" / "urdf"


CLONE_NEWNET = 0x40000000


def pytest_configure(config: pytest.Config) -> None:
    """A pytest-xdist worker (`make test` runs two) gets a network namespace of its own, with its
    own loopback: the fixed ports of the devices the tests simulate (UR's 30004 and 29999, a
    cell's Zenoh endpoints, the CAN hub's) are then each worker's, and two workers never meet on
    them. Taken in the worker's main thread before any other starts: every thread and process
    the tests start inherits it. Where it cannot be had (not root), the workers share the host's
    loopback, and UR's port lock (`orccadd.ursim.process.PortsLock`) keeps them apart."""
    if not os.environ.get("PYTEST_XDIST_WORKER") or os.environ.get("ORCCADD_TEST_SHARED_NET"):
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(CLONE_NEWNET) != 0:
        return
    up = subprocess.run(["ip", "link", "set", "lo", "up"], capture_output=True, text=True, check=False)
    if up.returncode != 0:
        raise pytest.UsageError(f"a test worker's network namespace: ip link set lo up: {up.stderr.strip()}")


# Tests that take fixed paths of the machine run on one worker, one after the other (`--dist
# loadgroup`): the README's tours, the demo, and the shipped gripper configs' serial links
# (/tmp/orccadd-gripper, /tmp/orccadd-left-hand, /tmp/orccadd-right-hand). Each such module sets
# `pytestmark` to it (a marker added in a collection hook comes too late for pytest-xdist).
FIXED_PATHS = pytest.mark.xdist_group("fixed-paths")


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """A worker of `--dist loadgroup` checks that its groups took effect: pytest-xdist carries a
    test's group in its node id, and where pytest does not take that id (pytest-dev/pytest-xdist
    #1386) the tests of a group would run on two workers at once, silently."""
    if not getattr(config.option, "loadgroup", False):
        return
    lost = [i.nodeid for i in items if i.get_closest_marker("xdist_group") and "@" not in i.nodeid]
    if lost:
        raise pytest.UsageError(f"pytest-xdist's groups do not take effect with this pytest: {lost[0]}")


def pytest_sessionstart(session: pytest.Session) -> None:
    """Byte-compile the project's modules (only those changed since): the tests start hundreds of
    interpreters (orccadd and its command daemon, plant, compiler and simulator processes,
    orccadctl), and where PYTHONDONTWRITEBYTECODE is set, as on these machines, none of them
    caches what it compiles, so each compiled every module it imports again (~0.1 s a process)."""
    for package in ("orccadd", "tools"):
        compileall.compile_dir(ROOT / package, quiet=2)


def variant_text(base: Path, *edits: tuple[str, str]) -> str:
    """The text of `base` with each (old, new) replaced once; `old` must be present."""
    text = base.read_text().replace('"../urdf/', f'"{URDF_DIR}/')
    for old, new in edits:
        assert old in text, f"{old!r} not in {base.name}"
        text = text.replace(old, new, 1)
    return text


def _variant_writer(tmp_path: Path, default_base: Path, default_name: str) -> Callable[..., Path]:
    def make(*edits: tuple[str, str], base: Path = default_base, name: str = default_name) -> Path:
        p = tmp_path / name
        p.write_text(variant_text(base, *edits))
        return p

    return make


@pytest.fixture
def robot_variant(tmp_path: Path) -> Callable[..., Path]:
    """Write a variant of a shipped robot config (`make(*(old, new), base=...)`); its path."""
    return _variant_writer(tmp_path, UR5E, "robot.toml")


@pytest.fixture
def task_variant(tmp_path: Path) -> Callable[..., Path]:
    """Write a variant of the shipped move task; returns its path."""
    return _variant_writer(tmp_path, MOVE_TASK, "task.toml")


def _testdata_dir() -> Path | None:
    """The shared public test data (EDS/DCF files): $ORCCADD_TESTDATA, or ../shared/testdata
    next to the project, or /work/shared/testdata (these machines)."""
    import os

    for cand in (
        os.environ.get("ORCCADD_TESTDATA", ""),
        ROOT.parent / "shared/testdata",
        "/work/shared/testdata",
    ):
        if cand and Path(cand, "eds").is_dir():
            return Path(cand)
    return None


TESTDATA = _testdata_dir()


def eds(relative: str) -> Path:
    """A public EDS/DCF file by its path under testdata/eds/ (the test is skipped without them)."""
    if TESTDATA is None:
        pytest.skip("public EDS files not found (set ORCCADD_TESTDATA to shared/testdata)")
    return TESTDATA / "eds" / relative
