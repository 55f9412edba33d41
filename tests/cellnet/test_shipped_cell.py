"""configs/cell/ as shipped (copied with free loopback ports, a socket and certificates of the
test's own): the README's tour, two daemons, the console's status and the split hand-over."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.launch import DaemonProcess
from tests.cellnet.conftest import free_port
from tests.cellnet.test_console import ctl

ROOT = Path(__file__).resolve().parents[2]
CELL = ROOT / "configs/cell"


def copy_cell(tmp: Path, certs: Path) -> dict[str, Path]:
    ports = {"7447": str(free_port()), "7448": str(free_port())}
    out = {}
    for src in sorted(CELL.glob("*.toml")):
        text = src.read_text()
        for old, new in ports.items():
            text = text.replace(f"127.0.0.1:{old}", f"127.0.0.1:{new}")
        text = text.replace('"certs/', f'"{certs}/').replace('"../', f'"{ROOT}/configs/')
        text = text.replace("/tmp/orccadd-cell/", f"{tmp}/run/")
        (tmp / src.name).write_text(text)
        out[src.stem] = tmp / src.name
    return out


@pytest.fixture
def shipped(tmp_path: Path, certs: Path) -> Iterator[dict[str, Path]]:
    files = copy_cell(tmp_path, certs)
    daemons: list[DaemonProcess] = []
    try:
        for arm in ("arm-a", "arm-b"):
            sock = tmp_path / "run" / f"{arm}.sock"
            daemons.append(DaemonProcess(files[arm], sock, tmp_path / f"{arm}.log", up_timeout_s=60.0))
        yield files
    finally:
        for d in daemons:
            d.stop()


def test_the_shipped_cell_runs_the_handover_from_the_console(shipped: dict[str, Path]) -> None:
    console = ["--cell", str(shipped["console"])]
    r = ctl(*console, "cell", "status", "--json")
    assert sorted(json.loads(r.stdout)["robots"]) == ["arm-a", "arm-b"], r.stdout + r.stderr
    for robot, half in (("arm-b", "b"), ("arm-a", "a")):
        assert ctl(*console, "--robot", robot, "load", f"cell_handover_{half}").returncode == 0
        assert ctl(*console, "--robot", robot, "start").returncode == 0
    deadline = time.monotonic() + 90
    while True:
        robots = json.loads(ctl(*console, "cell", "status", "--json").stdout)["robots"]
        results = {name: r["result"]["result"] for name, r in robots.items()}
        if set(results.values()) == {"success"}:
            break
        assert time.monotonic() < deadline, robots
        time.sleep(0.5)
    viewer = ctl("--cell", str(shipped["viewer"]), "--robot", "arm-a", "abort")
    assert viewer.returncode != 0 and "not authorised" in viewer.stderr
