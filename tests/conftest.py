"""Shared fixtures: shipped configs, variants of them written to a temporary folder."""

from __future__ import annotations

import atexit
import compileall
import contextlib
import ctypes
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator
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
    # the daemons' compile cache (as systemd's CacheDirectory= says where): this run's own, so
    # that no test depends on what earlier runs compiled; each worker's, like its network
    os.environ["CACHE_DIRECTORY"] = tempfile.mkdtemp(prefix="orccadd-test-cache-")
    atexit.register(shutil.rmtree, os.environ["CACHE_DIRECTORY"], True)
    # and their deployments (StateDirectory=): this run's own too
    os.environ["STATE_DIRECTORY"] = tempfile.mkdtemp(prefix="orccadd-test-state-")
    atexit.register(shutil.rmtree, os.environ["STATE_DIRECTORY"], True)
    if not os.environ.get("PYTEST_XDIST_WORKER") or os.environ.get("ORCCADD_TEST_SHARED_NET"):
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(CLONE_NEWNET) != 0:
        return
    up = subprocess.run(["ip", "link", "set", "lo", "up"], capture_output=True, text=True, check=False)
    if up.returncode != 0:
        raise pytest.UsageError(f"a test worker's network namespace: ip link set lo up: {up.stderr.strip()}")


# Tests that run one at a time, on one pytest-xdist worker (`--dist loadgroup`), while the other
# worker runs the rest: a device chain of three processes at 500 Hz (a UR controller simulator,
# ur_rtde's link, orccadd's loop) needs most of a core, and so do several daemons' plants and
# loops together. Two such at once keep both cores over 95 % at SCHED_FIFO, and the kernel (6.12
# and later) then runs the time-shared tasks for 50 ms in one go, every real-time chain on that
# core stalled meanwhile (docs/status.md, "The test suite"); and the tests on fixed paths (the
# README's tours, the demo, the shipped gripper configs' serial links /tmp/orccadd-gripper,
# /tmp/orccadd-left-hand, /tmp/orccadd-right-hand). By module, or by a module's parameter (the
# backend a suite runs on): what is not here runs on either worker, beside one of these.
ONE_AT_A_TIME = pytest.mark.xdist_group("one-at-a-time")
ONE_AT_A_TIME_MODULES = (
    "tests/test_readme.py",  # fixed paths; UR, Dynamixel, CANopen, cell tours
    "tests/test_demo.py",  # fixed paths
    "tests/daemon/test_pick_place.py",  # fixed paths; UR chain and a Dynamixel gripper
    "tests/daemon/test_handover.py",  # fixed paths; two Dynamixel grippers
    "tests/daemon/test_gripper.py",  # a Dynamixel gripper on a pseudo-terminal
    "tests/daemon/test_ur_rtde.py",  # UR chains
    "tests/daemon/test_ur_missions.py",
    "tests/physres/test_ur_rtde.py",
    "tests/ursim/test_stock_ur_rtde.py",
    "tests/ursim/test_stock_faults.py",
    "tests/ursim/test_stock_force_io.py",
    "tests/ursim/test_stock_cb3.py",
    "tests/daemon/test_dynamixel.py",  # Dynamixel chains on pseudo-terminals
    "tests/daemon/test_ethercat.py",  # a 1 kHz EtherCAT line: SOEM, the slave simulator, the loop
    "tests/physres/test_ethercat402.py",
    "tests/ecatsim/test_stock_pysoem.py",
    "tests/physres/test_dynamixel.py",
    "tests/dxlsim/test_sdk.py",
    "tests/physres/test_sim_process.py",  # this process's loop against the plant's watchdog
    "tests/physres/test_fault_matrix.py",
    "tests/daemon/test_station.py",  # two arms: two plants and two loops
    "tests/cellnet/test_cell_missions.py",  # two or three daemons, each with its plant
    "tests/cellnet/test_cmdd_threads.py",
    "tests/cellnet/test_console.py",
    "tests/cellnet/test_hil_cell.py",
    "tests/cellnet/test_floods.py",
    "tests/cellnet/test_hostile_peers.py",
    "tests/cellnet/test_impostors.py",
    "tests/cellnet/test_ros2_daemon.py",
    "tests/cellnet/test_shipped_cell.py",
    "tests/cellnet/test_tune_under_flood.py",
)
# in these modules, the tests on these backends
ONE_AT_A_TIME_BACKENDS = {
    "tests/physres/test_contract.py": ("ur_rtde", "dynamixel", "sim_process", "ethercat402"),
    "tests/daemon/test_same_mission.py": ("ur_rtde", "dynamixel", "ethercat402"),
    "tests/daemon/test_line_demo.py": ("ur_rtde",),
}
ONE_AT_A_TIME_TESTS = ("tests/daemon/test_peg_in_hole.py::test_the_same_mission_on_the_ur_simulator",)


def one_at_a_time(nodeid: str) -> bool:
    """Whether the test `nodeid` runs in the one-at-a-time group."""
    module, _, rest = nodeid.partition("::")
    if module in ONE_AT_A_TIME_MODULES or nodeid in ONE_AT_A_TIME_TESTS:
        return True
    param = rest.partition("[")[2].rstrip("]")
    return param in ONE_AT_A_TIME_BACKENDS.get(module, ())


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the one-at-a-time tests, before pytest-xdist's worker reads the marks."""
    for item in items:
        if one_at_a_time(item.nodeid):
            item.add_marker(ONE_AT_A_TIME)


ONE_AT_A_TIME_NICE = -5  # the time-shared processes of the one-at-a-time test: ~10x the share
OTHERS_NICE = 5  # of the other worker's (CFS weights 3121 and 335)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    """On a pytest-xdist worker, the one-at-a-time test's time-shared processes (orccadctl, the
    command daemon, the mission compiler, the test itself) come first: the other worker's tests
    take the time they leave, and the one-at-a-time tests, the longest chain of the run, go as
    fast as alone. Nice values are per thread, and what this thread starts inherits them."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        yield
        return
    nice = ONE_AT_A_TIME_NICE if item.get_closest_marker("xdist_group") else OTHERS_NICE
    with contextlib.suppress(PermissionError):  # not root: a raise is refused, all run alike
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    yield


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session: pytest.Session) -> None:
    """A worker of `--dist loadgroup` checks that its groups took effect: pytest-xdist carries a
    test's group in its node id, and where pytest does not take that id (pytest-dev/pytest-xdist
    #1386) the tests of a group would run on two workers at once, silently."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    lost = [i.nodeid for i in session.items if i.get_closest_marker("xdist_group") and "@" not in i.nodeid]
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
