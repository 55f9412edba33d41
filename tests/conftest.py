"""Shared fixtures: shipped configs, variants of them written to a temporary folder."""

from __future__ import annotations

import compileall
import fcntl
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
UR5E = ROOT / "configs" / "robots" / "sim-ur5e.toml"
PANDA = ROOT / "configs" / "robots" / "sim-panda.toml"
MOVE_TASK = ROOT / "configs" / "tasks" / "move_joints.toml"
URDF_DIR = ROOT / "configs" / "urdf"


def pytest_sessionstart(session: pytest.Session) -> None:
    """Byte-compile the project's modules (only those changed since): the tests start hundreds of
    interpreters (orccadd and its command daemon, plant, compiler and simulator processes,
    orccadctl), and where PYTHONDONTWRITEBYTECODE is set, as on these machines, none of them
    caches what it compiles, so each compiled every module it imports again (~0.1 s a process)."""
    for package in ("orccadd", "tools"):
        compileall.compile_dir(ROOT / package, quiet=2)


@pytest.fixture(autouse=True)
def _alone_or_together(request: pytest.FixtureRequest) -> Iterator[None]:
    """With `pytest -n 2` (make test), two workers run tests side by side. A test marked `alone`
    (its figures are real-time timings that another worker's real-time processes would disturb)
    runs with nothing beside it: a readers-writer lock between the workers, by `flock` on two
    files, the turnstile keeping new tests out while an `alone` test waits for the running one."""
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run is None:  # one process: nothing runs beside anything
        yield
        return
    alone = request.node.get_closest_marker("alone") is not None
    base = Path(tempfile.gettempdir()) / f"orccadd-tests-{run}"
    with open(f"{base}.turnstile", "a") as turnstile, open(f"{base}.lock", "a") as lock:
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        try:
            fcntl.flock(lock, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        finally:
            if not alone:
                fcntl.flock(turnstile, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
            fcntl.flock(turnstile, fcntl.LOCK_UN)


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
