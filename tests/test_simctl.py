"""`python -m orccadd.simctl`: the control protocol's requests made from a command line, the
replies shown, the errors in words; its list of faults is each simulator's own."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from orccadd.runtime import sim_control
from orccadd.runtime.sim_control import Injection
from orccadd.runtime.threads import ThreadGroup
from orccadd.simctl import FAULTS, main
from orccadd.simproc import control_address
from tests.conftest import ROOT

STATUS = {
    "q_rad": [0.0, -1.5708],
    "dq_rad_s": [0.0, 0.0],
    "devices": [sim_control.device("controller", "RUNNING", "PROTECTIVE_STOP")],
    "safety_mode": "PROTECTIVE_STOP",
    "wall": None,
    "ports": {"rtde": 30004},
}


class Channel:
    """A control channel served as the simulators serve theirs, recording the injections; one
    named `meteor` is refused."""

    def __init__(self, srv: socket.socket, address: str) -> None:
        self.address = address
        self.injected: list[Injection] = []
        self.threads = ThreadGroup("test-channel")
        self.threads.start(sim_control.serve, srv, self._inject, lambda: STATUS, self.threads, name="serve")
        self.srv = srv

    def _inject(self, req: Injection) -> None:
        if req.fault == "meteor":
            raise ValueError("unknown fault 'meteor' (faults: wall, push)")
        self.injected.append(req)

    def close(self) -> None:
        self.srv.close()
        self.threads.join(5.0)


@pytest.fixture(params=["tcp", "unix"])
def channel(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Channel]:
    if request.param == "tcp":
        srv = socket.create_server(("127.0.0.1", 0))
        address = f"127.0.0.1:{srv.getsockname()[1]}"
    else:
        srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        srv.bind(str(tmp_path / "sim.control"))
        srv.listen()
        address = str(tmp_path / "sim.control")
    c = Channel(srv, address)
    yield c
    c.close()


def test_inject_sends_the_fault_its_device_and_its_parameters_read_as_json(
    channel: Channel, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [channel.address, "inject", "wall", "point_m=[0.5,0,0.2]", "normal=[0,0,1]", "stiffness_n_m=5000"]
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out) == {"ok": True}
    assert (
        main([channel.address, "inject", "drop_connection", "ports=all", "value=true", "--device", "3"]) == 0
    )
    assert main([channel.address, "inject", "object", "--device", "1", "at_rad=0.9", "closing=-1"]) == 0
    assert channel.injected == [
        Injection("wall", None, {"point_m": [0.5, 0, 0.2], "normal": [0, 0, 1], "stiffness_n_m": 5000}),
        Injection("drop_connection", 3, {"ports": "all", "value": True}),
        Injection("object", 1, {"at_rad": 0.9, "closing": -1}),
    ]


def test_status_in_words_and_in_json(channel: Channel, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([channel.address, "status"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["q_rad", "0.0000", "-1.5708"]
    assert lines[2].split() == ["device", "controller", "RUNNING,", "fault:", "PROTECTIVE_STOP"]
    assert "safety_mode             PROTECTIVE_STOP" in lines
    assert "wall                    null" in lines and "ports                   rtde 30004" in lines
    assert main([channel.address, "status", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"ok": True, **STATUS}


def test_a_refusal_is_the_simulators_words_and_exit_1(
    channel: Channel, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([channel.address, "inject", "meteor"]) == 1
    err = capsys.readouterr().err
    assert err.strip() == "python -m orccadd.simctl: error: unknown fault 'meteor' (faults: wall, push)"


def test_nobody_listening_is_exit_2_naming_the_address(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as s:
        port = s.getsockname()[1]  # free once closed
    assert main([f"127.0.0.1:{port}", "status"]) == 2
    err = capsys.readouterr().err
    assert f"no answer from the simulator's control channel 127.0.0.1:{port} (Connection refused)" in err


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["nowhere", "status"], "control address (='nowhere') must be HOST:PORT or a UNIX socket's path"),
        (["127.0.0.1:99999", "status"], "must be HOST:PORT"),
        (["127.0.0.1:1", "inject", "wall", "point_m"], "parameter 'point_m' must be KEY=VALUE"),
        (["127.0.0.1:1", "inject", "wall", "2x=1"], "parameter '2x=1' must be KEY=VALUE, KEY a name"),
        (["127.0.0.1:1", "inject", "wall", "device=3"], "give the device as --device N"),
        (["127.0.0.1:1", "inject", "wall", "inject=push"], "the fault is the FAULT argument"),
        (["127.0.0.1:1", "inject", "push", "duration_s=1", "duration_s=2"], "'duration_s' given twice"),
        (["127.0.0.1:1", "inject", "overload", "--device", "three"], "invalid int value: 'three'"),
        (
            ["127.0.0.1:1", "inject", "object", "--device", "1", "at_rad"],
            "parameter 'at_rad' must be KEY=VALUE",
        ),
        (
            ["127.0.0.1:1", "inject", "object", "--device", "1", "--devce", "2"],
            "unrecognized argument '--devce'",
        ),
        (["127.0.0.1:1", "status", "x=1"], "unrecognized argument 'x=1'"),
        (
            ["127.0.0.1:1", "--timeout-s", "-1", "status"],
            "--timeout-s (='-1') must be a number of seconds above 0",
        ),
    ],
)
def test_bad_arguments_are_exit_2_saying_what_is_allowed(
    argv: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert words in capsys.readouterr().err


def test_a_control_address_is_host_port_or_a_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert control_address("127.0.0.1:4711") == ("127.0.0.1", 4711)
    assert control_address("/tmp/orccadd-gripper.control") == "/tmp/orccadd-gripper.control"
    monkeypatch.chdir(tmp_path)
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:  # `dxlsim --control here.control`
        s.bind("here.control")
        assert control_address("here.control") == "here.control"
    with pytest.raises(ValueError, match="must be HOST:PORT or a UNIX socket's path"):
        control_address("nothing.control")


def test_the_help_lists_each_simulators_own_faults() -> None:
    """The names --help lists are the ones each simulator's `inject` takes (its FAULTS)."""
    from orccadd.drivesim.simulator import FAULTS as DRIVE_FAULTS
    from orccadd.dxlsim.chain import FAULTS as DXL_FAULTS
    from orccadd.plantsim.control import FAULTS as PLANT_FAULTS
    from orccadd.ursim.simulator import DIGITAL_INPUTS, WORLD
    from orccadd.ursim.simulator import FAULTS as UR_FAULTS

    listed = {sim: [name for name, _ in faults] for sim, (_, faults) in FAULTS.items()}
    assert sorted(listed["ursim"]) == sorted([*UR_FAULTS, *WORLD, *DIGITAL_INPUTS])
    assert sorted(listed["drivesim"]) == sorted(DRIVE_FAULTS)
    assert sorted(listed["dxlsim"]) == sorted(DXL_FAULTS)
    assert sorted(listed["plantsim"]) == sorted(PLANT_FAULTS)
    out = subprocess.run(
        [sys.executable, "-m", "orccadd.simctl", "--help"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    for sim, names in listed.items():
        assert f"  {sim}: " in out.stdout
        assert all(f"    {n} " in out.stdout or out.stdout.count(f"    {n}\n") for n in names), sim
