"""The README's tours run as written: each bus's commands, in order, in a shell, with the paths
made absolute and the sockets in the test's directory. A background command (`… &`) is waited
for as a person would before typing the next line: a simulator until it says it is ready, orccadd
until its socket answers. The mission each tour starts must end in success."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from orccadd.ctl.client import Client, ClientError
from orccadd.ursim.process import PortsLock
from tests.conftest import ROOT

README = (ROOT / "README.md").read_text()
MORE_TOURS = (ROOT / "docs" / "tours.md").read_text()
# a terminal's view, a stream until Ctrl-C, and the shell's own job control
INTERACTIVE = ("orccadctl top", "--follow", "kill %")
READY_WORDS = ("ready", "listening on")
CELL_LOGS = Path("/tmp/orccadd-cell/logs")  # configs/cell/*.toml's sockets' directory, its logs


def tours() -> dict[str, str]:
    """Each tour's shell block, by its bold title's first words: the README's, then
    docs/tours.md's."""
    tour = README.split("## A five-minute tour", 1)[1].split("\n## ", 1)[0] + MORE_TOURS
    found = re.findall(r"\*\*([^*]+)\*\*.*?```sh\n(.*?)```", tour, re.S)
    return {title.split(",")[0].split(" (")[0]: block for title, block in found}


def test_the_readme_has_a_tour_per_bus() -> None:
    assert list(tours()) == [
        "The simulated arm",
        "The tool in task space",
        "A UR arm over RTDE",
        "A Dynamixel chain",
        "CANopen CiA 402 drives",
        "EtherCAT CiA 402 drives",
        "From simulation to the robot and back",
        "Two arms in one daemon",
        "An arm with its gripper",
        "Two robot PCs in one cell",
        "From the console to a robot PC of the cell and back",
    ]


def allowed_exit(line: str) -> int:
    """The exit status a tour's line says it ends with (`# exit 1: ...`, a compare that finds
    differences), else 0."""
    m = re.search(r"#\s*exit (\d+)\b", line)
    return int(m.group(1)) if m else 0


def localised(line: str, tmp: Path) -> str:
    line = line.split("  #")[0].strip()
    line = re.sub(r"/tmp/(\w+)\.sock", lambda m: str(tmp / f"{m.group(1)}.sock"), line)
    line = re.sub(r"(^|\s|=)\.venv/", lambda m: f"{m.group(1)}{ROOT}/.venv/", line)
    return re.sub(r"(^|\s|=)configs/", lambda m: f"{m.group(1)}{ROOT}/configs/", line)


class Shell:
    """The tour's commands in order, its background processes stopped at the end (orccadd first:
    the daemon's clients before the simulators they talk to)."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.env = {**os.environ}
        self.background: list[tuple[str, subprocess.Popen[bytes]]] = []

    def run(self, line: str, allowed_exit: int = 0) -> None:
        if line.startswith("export "):
            name, _, value = line.removeprefix("export ").partition("=")
            self.env[name] = value
            return
        if line.endswith("&"):
            self._start(line.removesuffix("&").strip())
            return
        r = subprocess.run(["bash", "-c", line], cwd=self.tmp, env=self.env, capture_output=True, timeout=120)
        assert r.returncode in (0, allowed_exit), (
            f"{line}\n{r.stdout.decode()[-2000:]}\n{r.stderr.decode()[-2000:]}"
        )

    def _start(self, line: str) -> None:
        out = self.tmp / f"background-{len(self.background)}.out"  # a file: never a full pipe
        with out.open("wb") as f:
            p = subprocess.Popen(
                ["bash", "-c", f"exec {line}"], cwd=self.tmp, env=self.env, start_new_session=True,
                stdout=f, stderr=subprocess.STDOUT,
            )  # fmt: skip
        self.background.append((line, p))
        socket = re.search(r"--socket (\S+)", line)
        if "orccadd --config" in line and socket:
            self._wait_daemon(socket.group(1), p)
        else:
            self._wait_ready(line, p, out)

    def _wait_ready(self, line: str, p: subprocess.Popen[bytes], out: Path, timeout_s: float = 60.0) -> None:
        end = time.monotonic() + timeout_s
        while not any(w in (seen := out.read_text(errors="replace")) for w in READY_WORDS):
            assert p.poll() is None and time.monotonic() < end, f"{line}: not ready\n{seen[-2000:]}"
            time.sleep(0.1)

    def _wait_daemon(self, socket: str, p: subprocess.Popen[bytes], timeout_s: float = 90.0) -> None:
        end = time.monotonic() + timeout_s
        while True:
            try:
                with Client(socket, timeout_s=5.0) as c:
                    c.call("ping")
                    return
            except (ClientError, OSError) as e:
                assert p.poll() is None and time.monotonic() < end, (
                    f"orccadd at {socket} did not come up: {e}"
                )
                time.sleep(0.2)

    def background_output(self, tail_bytes: int = 3000) -> str:
        out = []
        for i, (line, _) in enumerate(self.background):
            text = (self.tmp / f"background-{i}.out").read_text(errors="replace")
            out.append(f"--- {line}\n{text[-tail_bytes:]}")
        return "\n".join(out)

    def __enter__(self) -> Shell:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        for _, p in sorted(self.background, key=lambda lp: "orccadd --config" not in lp[0]):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGKILL)
                    p.wait(timeout=10)


@pytest.mark.timeout(300)
@pytest.mark.parametrize("tour", list(tours()))
def test_each_tour_runs_as_written_and_its_mission_succeeds(tour: str, tmp_path: Path) -> None:
    # the UR simulator serves UR's fixed ports: the lock every test's simulator takes keeps any
    # other off them while this tour's own runs
    ports = PortsLock(300.0) if "orccadd.ursim" in tours()[tour] else contextlib.nullcontext()
    # the shipped cell's daemons log into a fixed directory: a run before this one left its logs
    # there (a tour's `log start --name run.csv` would find its name taken)
    cell = "configs/cell/" in tours()[tour]
    if cell:
        shutil.rmtree(CELL_LOGS, ignore_errors=True)
    with ports, Shell(tmp_path) as shell:
        try:
            run_tour(tour, shell, tmp_path)
        except AssertionError as e:  # what the background processes said, to find out why
            raise AssertionError(f"{e}\n{shell.background_output()}") from None
    if cell:
        shutil.rmtree(CELL_LOGS, ignore_errors=True)


def run_tour(tour: str, shell: Shell, tmp_path: Path) -> None:
    raw = [x for x in tours()[tour].splitlines() if x.strip()]
    socket = ""
    for written in raw:
        line = localised(written, tmp_path)
        if any(word in line for word in INTERACTIVE):
            continue
        shell.run(line, allowed_exit(written))
        if m := re.search(r"--socket (\S+)", line):
            socket = m.group(1)
        socket = shell.env.get("ORCCADD_SOCKET", socket)
    if "ORCCADD_CELL" in shell.env:
        return cell_succeeded(shell, sum("orccadd --config" in x for x in raw))
    assert socket, "the tour names no socket"
    end = time.monotonic() + 120
    with Client(socket, timeout_s=10.0) as c:
        while (s := c.call("status"))["state"] == "running":
            assert time.monotonic() < end, s
            time.sleep(0.2)
    assert s["result"] == "success" and not s["faulted"], s


def cell_succeeded(shell: Shell, daemons: int) -> None:
    """A cell's tour: each of its `daemons` daemons' mission ended in success, as the console
    sees them."""
    import json
    import sys

    end = time.monotonic() + 120
    while True:
        r = subprocess.run(
            [sys.executable, "-m", "orccadd.cli", "cell", "status", "--json"],
            env=shell.env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        robots = json.loads(r.stdout)["robots"] if r.stdout else {}
        results = [v["result"]["result"] for v in robots.values() if v.get("ok")]
        if len(robots) >= daemons and results == ["success"] * len(robots):
            return
        assert time.monotonic() < end, (r.stdout, r.stderr)
        time.sleep(0.5)
