"""Stock pysoem (SOEM) against the EtherCAT slave simulator, through nothing but its own API: the
scan, the SII's identities, CoE SDO (expedited, normal and complete access; an abort), the PDO
mapping of `config_map`, distributed clocks, the state walk with AL status codes, the cyclic
exchange moving the drives, and the simulator's faults as a master sees them."""

from __future__ import annotations

import os
import shutil
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pysoem = pytest.importorskip("pysoem")

from orccadd.ecatsim.process import EcatSimProcess  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "robots" / "ethercat-6axis-sim.toml"
INTERFACE = "ecm0"
PERIOD_NS = 1_000_000
RX = struct.Struct("<HiihbB")  # controlword, target position, target velocity, target torque, mode, gap
TX = struct.Struct("<HiihbBH")  # statusword, position, velocity, torque, mode display, gap, error code

pytestmark = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("ip") is None, reason="the simulator's link needs root and iproute2"
)


@pytest.fixture
def sim() -> Iterator[EcatSimProcess]:
    with EcatSimProcess(CONFIG, "--priority", "70") as process:
        yield process


@pytest.fixture
def master(sim: EcatSimProcess) -> Iterator[pysoem.Master]:
    m = pysoem.Master()
    m.always_release_gil = True  # SOEM waits for each frame: the simulator is another process anyway
    m.open(INTERFACE)
    try:
        yield m
    finally:
        m.close()


def _to_op(m: pysoem.Master, dc: bool = True) -> None:
    assert m.config_init() == 6

    def setup(position: int) -> None:
        m.slaves[position - 1].sdo_write(0x1C32, 1, struct.pack("<H", 2 if dc else 1))

    for s in m.slaves:
        s.config_func = setup
    if dc:
        assert m.config_dc()
        for s in m.slaves:
            s.dc_sync(True, PERIOD_NS)
    assert m.config_map() == 6 * (RX.size + TX.size)
    assert m.state_check(pysoem.SAFEOP_STATE, 500_000) == pysoem.SAFEOP_STATE
    deadline = time.monotonic() + 2.0  # with DC, OP waits for the first SYNC0 (AL status 0x002D)
    while True:
        _cycle(m, 0x00)
        m.state = pysoem.OP_STATE
        m.write_state()
        if m.state_check(pysoem.OP_STATE, 5_000) == pysoem.OP_STATE:
            return
        assert time.monotonic() < deadline, [hex(s.al_status) for s in m.slaves]
        m.read_state()
        assert all(s.al_status in (0, 0x002D) for s in m.slaves)
        m.state = pysoem.SAFEOP_STATE | pysoem.STATE_ACK  # the error acknowledged
        m.write_state()


def _cycle(m: pysoem.Master, controlword: int, targets: list[int] | None = None) -> int:
    for k, s in enumerate(m.slaves):
        position = TX.unpack_from(s.input)[1] if targets is None else targets[k]
        s.output = RX.pack(controlword, position, 0, 0, 8, 0)
    m.send_processdata()
    wkc = int(m.receive_processdata(10_000))
    time.sleep(PERIOD_NS * 1e-9)
    return wkc


def _inputs(m: pysoem.Master) -> list[tuple[int, ...]]:
    return [TX.unpack_from(s.input) for s in m.slaves]


def test_the_scan_finds_each_slave_as_its_sii_says(master: pysoem.Master) -> None:
    assert master.config_init() == 6
    for s in master.slaves:
        assert (s.man, s.id, s.rev) == (0x0, 0x402, 0x1)
        assert s.name == "orccadd CiA 402 drive (simulated)"
    assert master.read_state() == pysoem.PREOP_STATE


def test_sdo_reads_writes_and_aborts_as_a_coe_server(master: pysoem.Master) -> None:
    assert master.config_init() == 6
    s = master.slaves[2]
    assert struct.unpack("<I", s.sdo_read(0x1018, 2))[0] == 0x402  # the dictionary agrees with the SII
    s.sdo_write(0x6065, 0, struct.pack("<I", 12345))
    assert struct.unpack("<I", s.sdo_read(0x6065, 0))[0] == 12345
    mapping = s.sdo_read(0x1A00, 0, ca=True)  # complete access: sub 0 then every entry
    assert mapping[0] == 7 and struct.unpack_from("<I", mapping, 2)[0] == 0x60410010
    with pytest.raises(pysoem.SdoError) as e:
        s.sdo_read(0x2000, 0)
    assert e.value.abort_code == 0x06020000  # no such object
    with pytest.raises(pysoem.SdoError) as e:
        s.sdo_write(0x6041, 0, struct.pack("<H", 1))
    assert e.value.abort_code == 0x06010002  # read only


def test_safe_op_is_refused_with_dc_synchronisation_but_no_sync0(master: pysoem.Master) -> None:
    assert master.config_init() == 6

    def setup(position: int) -> None:
        master.slaves[position - 1].sdo_write(0x1C32, 1, struct.pack("<H", 2))

    for s in master.slaves:
        s.config_func = setup
    master.config_map()
    assert master.state_check(pysoem.SAFEOP_STATE, 200_000) != pysoem.SAFEOP_STATE
    master.read_state()
    for s in master.slaves:
        assert s.al_status == 0x0030  # invalid DC SYNC configuration
        assert s.state == pysoem.PREOP_STATE | pysoem.STATE_ERROR


def test_the_cyclic_exchange_enables_and_moves_the_drives(master: pysoem.Master) -> None:
    _to_op(master)
    expected = master.expected_wkc
    assert expected == 6 * 3
    wkcs = [_cycle(master, cw) for cw in [0x06] * 20 + [0x07] * 20 + [0x0F] * 20]
    assert sum(w == expected for w in wkcs) >= len(wkcs) - 3  # the odd late frame on a busy machine
    assert all(st & 0x6F == 0x27 for st, *_ in _inputs(master))  # OPERATION ENABLED
    start = [p for _s, p, *_ in _inputs(master)]
    for k in range(1, 200):  # 0.02 rad over 0.2 s on the first joint
        _cycle(master, 0x0F, [start[0] + round(k * 0.0001 * 131072 * 101 / 6.2832), *start[1:]])
    moved = _inputs(master)[0][1] - start[0]
    assert moved == pytest.approx(0.0199 * 131072 * 101 / 6.2832, rel=0.2)
    assert master.dc_time > 0  # the reference clock's time, carried back in every frame


def test_a_drive_fault_shows_in_the_inputs_and_as_an_emergency(
    sim: EcatSimProcess, master: pysoem.Master
) -> None:
    _to_op(master)
    for cw in [0x06] * 20 + [0x0F] * 20:
        _cycle(master, cw)
    emergencies: list[int] = []
    master.slaves[1].add_emergency_callback(lambda e: emergencies.append(e.error_code))
    sim.inject("overcurrent", device=2)
    for _ in range(200):
        _cycle(master, 0x0F)
        if _inputs(master)[1][0] & 0x4F == 0x08:
            break
    status, *_rest, error = _inputs(master)[1]
    assert status & 0x4F == 0x08 and error == 0x2310  # FAULT, over-current
    master.slaves[1].mbx_receive()
    assert emergencies == [0x2310]


def test_an_unplugged_slave_leaves_the_working_counter_short(
    sim: EcatSimProcess, master: pysoem.Master
) -> None:
    _to_op(master, dc=False)
    sim.inject("unplug", device=5)
    assert _cycle(master, 0x06) == 4 * 3  # slaves 5 and 6 no longer on the line
    sim.inject("lose_frames", frames=1)
    assert _cycle(master, 0x06) <= 0  # nothing came back
    sim.inject("replug")
    assert _cycle(master, 0x06) == 6 * 3
