"""The RTDE, dashboard and script servers over loopback on ephemeral ports, with a client
written here from the RTDE guide (stock ur_rtde against the fixed ports: test_stock_ur_rtde)."""

from __future__ import annotations

import itertools
import socket
import struct
import threading
import time
from collections.abc import Iterator

import pytest

from orccadd.config.robot import RobotConfig
from orccadd.ursim.control_script import register_offsets
from orccadd.ursim.dashboard import Session, answer
from orccadd.ursim.script_server import split_programs
from orccadd.ursim.series import E_SERIES
from orccadd.ursim.simulator import UrSimulator
from orccadd.ursim.states import RobotMode, RuntimeState, SafetyMode

EPHEMERAL = {"rtde": 0, "dashboard": 0, "primary": 0, "secondary": 0, "realtime": 0}


@pytest.fixture
def sim(ur5e: RobotConfig) -> Iterator[UrSimulator]:
    s = UrSimulator(ur5e, E_SERIES, ports=EPHEMERAL, boot_running=True)
    s.open()
    stop = threading.Event()
    runner = threading.Thread(target=s.run, args=(stop.is_set,), daemon=True)
    runner.start()
    try:
        yield s
    finally:
        stop.set()
        runner.join(5)
        s.close()


class RtdeClient:
    """The RTDE protocol from the client's side, as the RTDE guide describes it."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)

    def send(self, kind: str, payload: bytes = b"") -> None:
        self.sock.sendall(struct.pack(">HB", 3 + len(payload), ord(kind)) + payload)

    def recv(self) -> tuple[str, bytes]:
        size, kind = struct.unpack(">HB", self._exact(3))
        return chr(kind), self._exact(size - 3)

    def recv_not_data(self) -> tuple[str, bytes]:
        while True:
            kind, payload = self.recv()
            if kind != "U":
                return kind, payload

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            assert chunk, "closed by the controller"
            buf += chunk
        return buf

    def request(self, kind: str, payload: bytes = b"") -> bytes:
        self.send(kind, payload)
        got, reply = self.recv_not_data()
        assert got == kind
        return reply

    def setup_outputs(self, names: str, hz: float) -> tuple[int, str]:
        reply = self.request("O", struct.pack(">d", hz) + names.encode())
        return reply[0], reply[1:].decode()

    def setup_inputs(self, names: str) -> tuple[int, str]:
        reply = self.request("I", names.encode())
        return reply[0], reply[1:].decode()

    def close(self) -> None:
        self.sock.close()


def test_version_negotiation_accepts_only_protocol_2(sim: UrSimulator) -> None:
    c = RtdeClient(sim.servers["rtde"].port)
    assert c.request("V", struct.pack(">H", 1)) == b"\x00"
    assert c.request("V", struct.pack(">H", 2)) == b"\x01"
    assert struct.unpack(">4I", c.request("v")) == (5, 26, 0, 0)
    c.close()


def test_unknown_output_names_are_not_found_and_refuse_the_recipe(sim: UrSimulator) -> None:
    c = RtdeClient(sim.servers["rtde"].port)
    assert c.setup_outputs("timestamp,actual_q,no_such_field", 500) == (0, "DOUBLE,VECTOR6D,NOT_FOUND")
    assert c.setup_outputs("timestamp,actual_q,robot_mode,safety_status_bits", 500) == (
        1,
        "DOUBLE,VECTOR6D,INT32,UINT32",
    )
    c.close()


def test_an_input_another_client_writes_is_in_use_until_it_leaves(sim: UrSimulator) -> None:
    port = sim.servers["rtde"].port
    a, b = RtdeClient(port), RtdeClient(port)
    assert a.setup_inputs("input_int_register_0,input_double_register_0") == (1, "INT32,DOUBLE")
    assert a.setup_inputs("input_int_register_0") == (2, "INT32")  # its own recipes may share
    assert b.setup_inputs("input_double_register_0,speed_slider_fraction") == (0, "IN_USE,DOUBLE")
    assert b.setup_inputs("input_int_register_99") == (0, "NOT_FOUND")
    a.close()
    deadline = time.monotonic() + 5
    while b.setup_inputs("input_double_register_0")[0] == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert b.setup_inputs("input_int_register_0")[0] > 0
    b.close()


def test_data_packages_flow_at_the_asked_frequency_until_paused(sim: UrSimulator) -> None:
    c = RtdeClient(sim.servers["rtde"].port)
    assert c.setup_outputs("timestamp,actual_q,runtime_state", 125.0)[0] == 1
    assert c.request("S") == b"\x01"
    stamps = []
    for _ in range(20):
        kind, payload = c.recv()
        assert kind == "U" and payload[0] == 1
        t, *q_and_state = struct.unpack(">d6dI", payload[1:])
        stamps.append(t)
        assert q_and_state[-1] == RuntimeState.STOPPED
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    # every 4th cycle of 2 ms (a cycle this loaded machine skips makes a longer gap)
    assert min(gaps) > 0.008 - 1e-6
    assert any(g == pytest.approx(0.008, abs=1e-6) for g in gaps)
    c.send("P")
    kind, reply = c.recv_not_data()
    assert (kind, reply) == ("P", b"\x01")
    c.sock.settimeout(0.2)
    with pytest.raises(TimeoutError):
        c.recv()  # nothing after the pause reply
    c.close()


def test_inputs_written_read_back_and_a_bad_package_gets_a_text_message(sim: UrSimulator) -> None:
    c = RtdeClient(sim.servers["rtde"].port)
    rid, _ = c.setup_inputs("input_double_register_5,input_int_register_7")
    assert c.setup_outputs("input_double_register_5,input_int_register_7", 500)[0] == 1
    c.send("U", bytes([rid]) + struct.pack(">di", 2.5, -7))
    assert c.request("S") == b"\x01"
    deadline = time.monotonic() + 2
    while True:
        kind, payload = c.recv()
        if kind == "U" and struct.unpack(">di", payload[1:]) == (2.5, -7):
            break
        assert time.monotonic() < deadline
    c.send("U", bytes([rid]) + b"\x00")  # too short for its recipe
    kind, payload = c.recv_not_data()
    assert kind == "M"
    text = payload[1 : 1 + payload[0]].decode()
    assert "refused" in text
    c.close()


def test_the_dashboard_greets_then_answers_line_by_line(sim: UrSimulator) -> None:
    s = socket.create_connection(("127.0.0.1", sim.servers["dashboard"].port), timeout=5)
    f = s.makefile("rwb")
    assert f.readline() == b"Connected: Universal Robots Dashboard Server\n"
    for line, reply in [
        ("robotmode", "Robotmode: RUNNING"),
        ("PolyscopeVersion", "URSoftware 5.26.0.0 (Jan 01 2026)"),
        ("power off", "Powering off"),
        ("robotmode", "Robotmode: POWER_OFF"),
        ("unlock protective stop", "Protective stop releasing"),
        ("safetystatus", "Safetystatus: NORMAL"),
        ("programState", "STOPPED <unnamed>"),
        ("bogus words", "could not understand: 'bogus words'"),
        ("quit", "Disconnected"),
    ]:
        f.write(line.encode() + b"\n")
        f.flush()
        assert f.readline().decode().rstrip("\n") == reply
    assert f.readline() == b""  # quit closes
    s.close()


def test_dashboard_commands_are_matched_whole_and_case_insensitively(sim: UrSimulator) -> None:
    ctl, session = sim.ctl, Session()
    assert answer(ctl, session, "  POWER   on ") == "Powering on"
    assert answer(ctl, session, "power onx").startswith("could not understand")
    assert answer(ctl, session, "popup hello there") == "showing popup"
    assert answer(ctl, session, "setUserRole operator") == "Setting user role: operator"
    assert answer(ctl, session, "getUserRole") == "OPERATOR"
    assert answer(ctl, session, "load /programs/x.urp") == "File not found: /programs/x.urp"
    assert answer(ctl, session, "play") == "Failed to execute: play"  # nothing to resume
    assert answer(ctl, session, "version") == "5.26.0.0"


def test_protective_stop_line_on_a_script_port(sim: UrSimulator) -> None:
    with socket.create_connection(("127.0.0.1", sim.servers["realtime"].port), timeout=5) as s:
        s.sendall(b"protective_stop()\n")
    deadline = time.monotonic() + 5
    while sim.ctl.safety_mode is not SafetyMode.PROTECTIVE_STOP:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert sim.ctl.robot_mode is RobotMode.RUNNING


def test_the_control_script_starts_when_sent_in_pieces(sim: UrSimulator) -> None:
    script = (
        b"def rtde_control():\n    global reg_offset_float = # float register offset\n0"
        b"    global reg_offset_int = # int register offset\n0\n"
        b'    textmsg("RTDE Control Script Loaded")\n    if True:\n        sync()\n    end\nend\n'
    )
    with socket.create_connection(("127.0.0.1", sim.servers["realtime"].port), timeout=5) as s:
        for i in range(0, len(script), 7):
            s.sendall(script[i : i + 7])
            time.sleep(0.001)
    deadline = time.monotonic() + 5
    while sim.ctl.runtime_state is not RuntimeState.PLAYING:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert sim.ctl.program_name == "rtde_control"


def test_split_programs_and_register_offsets() -> None:
    programs, rest = split_programs("\nsec s():\n  x = 1\nend\ntextmsg(1)\ndef p():\n  y()\n")
    assert programs == ["sec s():\n  x = 1\nend", "textmsg(1)"]
    assert rest == "def p():\n  y()\n"
    head = (
        "global reg_offset_float = # float register offset\n"
        "24    global reg_offset_int = # int register offset\n24 x"
    )
    assert register_offsets(head) == (24, 24)
    assert register_offsets("no offsets here") == (0, 0)
