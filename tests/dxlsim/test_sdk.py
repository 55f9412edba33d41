"""Stock dynamixel_sdk (ROBOTIS's own client, unmodified) against the simulator process on its
pseudo-terminal: ping, read/write, sync write and (fast) sync read, (fast) bulk read, reboot,
factory reset, injected faults. Timing is checked to orders of magnitude only (shared VM)."""

from __future__ import annotations

import math
import shutil
import statistics
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from orccadd.dxlsim.process import DxlSimProcess
from tests.conftest import ROOT

CONFIG = ROOT / "configs" / "robots" / "dxl-6axis-sim.toml"
IDS = (1, 2, 3, 4, 5, 6)
MODELS = (1120, 1120, 1120, 1020, 1020, 1020)  # XM540-W270 ×3, XM430-W350 ×3
GOAL_POSITION, PRESENT_POSITION, TORQUE_ENABLE, HARDWARE_ERROR = 116, 132, 64, 70
pytestmark = pytest.mark.timeout(60)


class Bus:
    """A controller's end: the SDK's port and packet handler on the simulator's link."""

    def __init__(self, port: str, baud: int) -> None:
        self.port = PortHandler(port)
        assert self.port.openPort() and self.port.setBaudRate(baud)
        self.ph = PacketHandler(2.0)

    def close(self) -> None:
        self.port.closePort()

    def positions(self) -> list[int]:
        out = []
        for i in IDS:
            value, result, _ = self.ph.read4ByteTxRx(self.port, i, PRESENT_POSITION)
            assert result == COMM_SUCCESS
            out.append(value)
        return out

    def torque_on(self, ids: tuple[int, ...] = IDS) -> None:
        for i in ids:
            value, result, _ = self.ph.read4ByteTxRx(self.port, i, PRESENT_POSITION)
            assert result == COMM_SUCCESS
            assert self.ph.write4ByteTxRx(self.port, i, GOAL_POSITION, value) == (COMM_SUCCESS, 0)
            assert self.ph.write1ByteTxRx(self.port, i, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)


def _start(config: Path, workdir: Path) -> DxlSimProcess:
    workdir.mkdir(exist_ok=True)
    return DxlSimProcess(config, "--port", str(workdir / "ttyDXL"))


@pytest.fixture(scope="module")
def workdir() -> Iterator[Path]:
    d = Path(tempfile.mkdtemp(prefix="dxl"))  # short: a UNIX socket path has ~100 characters
    try:
        yield d
    finally:
        shutil.rmtree(d, ignore_errors=True)


@pytest.fixture(scope="module")
def sim(workdir: Path) -> Iterator[DxlSimProcess]:
    p = _start(CONFIG, workdir)
    try:
        yield p
    finally:
        p.stop()


@pytest.fixture
def bus(sim: DxlSimProcess) -> Iterator[Bus]:
    b = Bus(sim.port, 4_000_000)
    try:
        yield b
    finally:
        b.close()


def test_ping_answers_every_model_number(bus: Bus) -> None:
    for i, model in zip(IDS, MODELS, strict=True):
        assert bus.ph.ping(bus.port, i) == (model, COMM_SUCCESS, 0)
    found, result = bus.ph.broadcastPing(bus.port)
    assert result == COMM_SUCCESS
    assert {i: m for i, (m, _fw) in found.items()} == dict(zip(IDS, MODELS, strict=True))


def test_read_write_and_eeprom_locked_while_torque_is_on(bus: Bus) -> None:
    assert bus.ph.write1ByteTxRx(bus.port, 1, 65, 1) == (COMM_SUCCESS, 0)  # LED
    assert bus.ph.read1ByteTxRx(bus.port, 1, 65) == (1, COMM_SUCCESS, 0)
    assert bus.ph.write1ByteTxRx(bus.port, 1, 9, 0) == (COMM_SUCCESS, 0)  # Return Delay Time: EEPROM
    bus.torque_on((1,))
    assert bus.ph.write1ByteTxRx(bus.port, 1, 11, 1) == (COMM_SUCCESS, 7)  # Access Error
    assert bus.ph.read1ByteTxRx(bus.port, 1, 11) == (3, COMM_SUCCESS, 0)  # unchanged
    assert bus.ph.write1ByteTxRx(bus.port, 1, TORQUE_ENABLE, 0) == (COMM_SUCCESS, 0)
    assert bus.ph.write1ByteTxRx(bus.port, 1, 9, 250) == (COMM_SUCCESS, 0)


def test_a_status_packet_holding_a_header_pattern_is_stuffed_and_read_back_intact(bus: Bus) -> None:
    # Homing Offset(20) = -1 and Moving Threshold(24) = 253: bytes 20-27 read FF FF FF FF FD 00 00 00
    assert bus.ph.write4ByteTxRx(bus.port, 2, 20, 0xFFFFFFFF) == (COMM_SUCCESS, 0)
    assert bus.ph.write4ByteTxRx(bus.port, 2, 24, 253) == (COMM_SUCCESS, 0)
    try:
        data, result, error = bus.ph.readTxRx(bus.port, 2, 20, 8)
        assert (bytes(data), result, error) == (bytes.fromhex("FF FF FF FF FD 00 00 00"), COMM_SUCCESS, 0)
    finally:
        assert bus.ph.write4ByteTxRx(bus.port, 2, 20, 0) == (COMM_SUCCESS, 0)
        assert bus.ph.write4ByteTxRx(bus.port, 2, 24, 10) == (COMM_SUCCESS, 0)


def test_sync_write_of_goals_then_sync_reads_show_the_motion(sim: DxlSimProcess, bus: Bus) -> None:
    start = bus.positions()
    bus.torque_on()
    write = GroupSyncWrite(bus.port, bus.ph, GOAL_POSITION, 4)
    for i, p in zip(IDS, start, strict=True):
        assert write.addParam(i, list((p + 200).to_bytes(4, "little")))
    assert write.txPacket() == COMM_SUCCESS
    read = GroupSyncRead(bus.port, bus.ph, 126, 10)  # current, velocity, position
    for i in IDS:
        assert read.addParam(i)
    moved: list[int] = []
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        assert read.fastSyncRead() == COMM_SUCCESS
        moved = [read.getData(i, PRESENT_POSITION, 4) - p for i, p in zip(IDS, start, strict=True)]
        if all(abs(m - 200) < 80 for m in moved):
            break
        time.sleep(0.05)
    assert all(abs(m - 200) < 80 for m in moved), moved
    assert read.txRxPacket() == COMM_SUCCESS  # the plain sync read agrees with the fast one
    assert all(
        abs(read.getData(i, PRESENT_POSITION, 4) - p - 200) < 80 for i, p in zip(IDS, start, strict=True)
    )
    q = sim.status()["q_rad"]  # the arm moved, not just a register
    assert abs(q[0] - (read.getData(1, PRESENT_POSITION, 4) - 2048) * 2 * math.pi / 4096) < 0.02
    for i in IDS:
        bus.ph.write1ByteTxRx(bus.port, i, TORQUE_ENABLE, 0)


def test_bulk_read_and_fast_bulk_read(bus: Bus) -> None:
    asked = {1: (0, 2), 2: (146, 1), 3: (PRESENT_POSITION, 4), 4: (0, 2), 5: (146, 1), 6: (144, 2)}
    expected = {1: 1120, 2: 30, 4: 1020, 5: 30, 6: 120}  # model numbers, 30 °C, 12.0 V
    read = GroupBulkRead(bus.port, bus.ph)
    for i, (address, length) in asked.items():
        assert read.addParam(i, address, length)
    for transaction in (read.txRxPacket, read.fastBulkRead):
        assert transaction() == COMM_SUCCESS
        got = {i: read.getData(i, a, n) for i, (a, n) in asked.items()}
        assert {i: got[i] for i in expected} == expected
        assert 0 < got[3] < 4096


def test_ping_and_read_take_the_wire_time_of_the_baud_rate(
    sim: DxlSimProcess, bus: Bus, workdir: Path
) -> None:
    def median_ms(b: Bus, n: int) -> float:
        times = []
        for _ in range(n):
            t0 = time.perf_counter()
            _, result, _ = b.ph.readTxRx(b.port, 1, 0, 147)
            times.append((time.perf_counter() - t0) * 1e3)
            assert result == COMM_SUCCESS
        return statistics.median(times)

    fast = median_ms(bus, 20)  # 158 bytes back at 4 Mbit/s: 0.4 ms, plus the 0.5 ms return delay
    slow_config = workdir / "slow.toml"
    slow_config.write_text(
        CONFIG.read_text().replace('"../urdf/', f'"{ROOT}/configs/urdf/').replace("4_000_000", "57_600")
    )
    slow = _start(slow_config, workdir / "slow")
    try:
        b = Bus(slow.port, 57_600)
        try:
            slow_ms = median_ms(b, 5)  # 158 + 14 bytes at 57,600 bit/s: 30 ms on the wire
        finally:
            b.close()
    finally:
        slow.stop()
    assert 0.4 < fast < 20.0
    assert 25.0 < slow_ms < 300.0


def test_reboot_clears_an_injected_overload(sim: DxlSimProcess, bus: Bus) -> None:
    bus.torque_on((3,))
    sim.inject("overload", device=3)
    value, result, error = bus.ph.read1ByteTxRx(bus.port, 3, HARDWARE_ERROR)
    assert (value, result, error) == (0x20, COMM_SUCCESS, 0x80)  # overload bit; alert in the status
    assert bus.ph.read1ByteTxRx(bus.port, 3, TORQUE_ENABLE) == (0, COMM_SUCCESS, 0x80)  # shut down
    assert bus.ph.write1ByteTxRx(bus.port, 3, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0x81)  # refused
    assert bus.ph.reboot(bus.port, 3) == (COMM_SUCCESS, 0x80)
    deadline = time.monotonic() + 3.0
    while bus.ph.ping(bus.port, 3)[1] != COMM_SUCCESS:
        assert time.monotonic() < deadline, "no answer after the reboot"
    assert bus.ph.read1ByteTxRx(bus.port, 3, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)
    bus.torque_on((3,))
    assert bus.ph.write1ByteTxRx(bus.port, 3, TORQUE_ENABLE, 0) == (COMM_SUCCESS, 0)


def test_factory_reset_restores_the_defaults(bus: Bus) -> None:
    assert bus.ph.write1ByteTxRx(bus.port, 4, 9, 0) == (COMM_SUCCESS, 0)  # Return Delay Time
    assert bus.ph.write1ByteTxRx(bus.port, 4, 11, 4) == (COMM_SUCCESS, 0)  # extended position
    assert bus.ph.factoryReset(bus.port, 4, 0x02) == (COMM_SUCCESS, 0)  # all but ID and baud rate
    deadline = time.monotonic() + 3.0
    while bus.ph.ping(bus.port, 4)[1] != COMM_SUCCESS:
        assert time.monotonic() < deadline, "no answer after the factory reset"
    assert bus.ph.read1ByteTxRx(bus.port, 4, 9) == (250, COMM_SUCCESS, 0)
    assert bus.ph.read1ByteTxRx(bus.port, 4, 11) == (3, COMM_SUCCESS, 0)


def test_an_unplugged_servo_times_out_and_answers_again_once_replugged(sim: DxlSimProcess, bus: Bus) -> None:
    sim.inject("unplug", device=5)
    try:
        assert bus.ph.ping(bus.port, 5)[1] == COMM_RX_TIMEOUT
        assert bus.ph.ping(bus.port, 6)[1] == COMM_SUCCESS
        read = GroupSyncRead(bus.port, bus.ph, PRESENT_POSITION, 4)
        for i in IDS:
            read.addParam(i)
        assert read.txRxPacket() != COMM_SUCCESS
        assert read.fastSyncRead() != COMM_SUCCESS  # the one packet stops where servo 5 should be
        read.removeParam(5)
        assert read.fastSyncRead() == COMM_SUCCESS
    finally:
        sim.inject("replug", device=5)
    deadline = time.monotonic() + 3.0
    while bus.ph.ping(bus.port, 5)[1] != COMM_SUCCESS:
        assert time.monotonic() < deadline, "no answer after the replug"


def test_crc_noise_corrupts_replies_at_about_the_injected_rate(sim: DxlSimProcess, bus: Bus) -> None:
    rate, n = 0.007, 300  # per byte; a 15-byte status packet: 1 - (1 - p)^15 = 10 % damaged
    sim.inject("noise", rate=rate)
    try:
        failed = sum(
            bus.ph.read4ByteTxRx(bus.port, 1 + k % 6, PRESENT_POSITION)[1] != COMM_SUCCESS for k in range(n)
        )
    finally:
        sim.inject("clear")
    expected = n * (1 - (1 - rate) ** 15)
    assert 0.4 * expected < failed < 2.0 * expected, (failed, expected)
    assert all(bus.ph.read4ByteTxRx(bus.port, i, PRESENT_POSITION)[1] == COMM_SUCCESS for i in IDS)


def test_the_link_and_the_control_socket_go_with_the_process(workdir: Path) -> None:
    p = _start(CONFIG, workdir / "short")
    port, control = Path(p.port), Path(p.control)
    assert port.is_symlink() and control.is_socket()
    assert p.stop() == 0
    assert not port.exists() and not port.is_symlink() and not control.exists()


def test_an_object_stops_a_current_limited_joint_and_its_current_shows_the_grip(
    sim: DxlSimProcess, bus: Bus
) -> None:
    """A gripper's grasp as its servo sees it: in current-based position mode (5) with a current
    limit, a goal beyond an object stops at the object, pressing it with the limited current; the
    object removed, the joint goes on to its goal."""
    servo, operating_mode, goal_current, present_current = 6, 11, 102, 126
    assert bus.ph.write1ByteTxRx(bus.port, servo, TORQUE_ENABLE, 0) == (COMM_SUCCESS, 0)
    assert bus.ph.write1ByteTxRx(bus.port, servo, operating_mode, 5) == (COMM_SUCCESS, 0)
    limit = 120  # × 2.69 mA: about 0.32 A
    assert bus.ph.write2ByteTxRx(bus.port, servo, goal_current, limit) == (COMM_SUCCESS, 0)
    start = bus.positions()[servo - 1]
    ticks_per_rad = 4096 / (2 * math.pi)
    q0 = (start - 2048) / ticks_per_rad
    sim.inject("object", device=servo, at_rad=q0 + 0.2, stiffness_nm_rad=20.0, closing=1)
    try:
        bus.torque_on((servo,))
        goal = start + round(0.6 * ticks_per_rad)
        assert bus.ph.write4ByteTxRx(bus.port, servo, GOAL_POSITION, goal) == (COMM_SUCCESS, 0)
        deadline = time.monotonic() + 5.0
        while True:  # until it rests against the object, pressing it
            st = sim.status()
            q, dq = st["q_rad"][servo - 1], st["dq_rad_s"][servo - 1]
            current, _, _ = bus.ph.read2ByteTxRx(bus.port, servo, present_current)
            current = current - 65536 if current >= 32768 else current
            if q > q0 + 0.15 and abs(dq) < 0.01 and abs(current) >= 0.8 * limit:
                break
            assert time.monotonic() < deadline, (q - q0, dq, current)
            time.sleep(0.02)
        assert 0.2 <= q - q0 < 0.3, q - q0  # at the object, a little into it: not at the goal
        assert abs(current) <= 1.05 * limit  # pressing with the limited current, no more
        sim.inject("remove_object", device=servo)
        deadline = time.monotonic() + 5.0
        while abs(bus.positions()[servo - 1] - goal) > 40:
            assert time.monotonic() < deadline, bus.positions()[servo - 1] - goal
            time.sleep(0.02)
    finally:
        sim.inject("remove_object", device=servo)
        bus.ph.write1ByteTxRx(bus.port, servo, TORQUE_ENABLE, 0)
        bus.ph.write1ByteTxRx(bus.port, servo, operating_mode, 3)


def test_a_lowered_current_limit_caps_the_grip_whatever_goal_current_says(
    sim: DxlSimProcess, bus: Bus
) -> None:
    """Current Limit(38) caps the current in current-based position mode (e-Manual): lowered
    after Goal Current(102) was set higher, the grip is the limit's."""
    servo, operating_mode, current_limit, goal_current, present_current = 6, 11, 38, 102, 126
    assert bus.ph.write1ByteTxRx(bus.port, servo, TORQUE_ENABLE, 0) == (COMM_SUCCESS, 0)
    assert bus.ph.write1ByteTxRx(bus.port, servo, operating_mode, 5) == (COMM_SUCCESS, 0)
    assert bus.ph.write2ByteTxRx(bus.port, servo, goal_current, 300) == (COMM_SUCCESS, 0)
    assert bus.ph.write2ByteTxRx(bus.port, servo, current_limit, 60) == (COMM_SUCCESS, 0)
    start = bus.positions()[servo - 1]
    ticks_per_rad = 4096 / (2 * math.pi)
    sim.inject("object", device=servo, at_rad=(start - 2048) / ticks_per_rad + 0.1, stiffness_nm_rad=20.0)
    try:
        bus.torque_on((servo,))
        assert bus.ph.write4ByteTxRx(bus.port, servo, GOAL_POSITION, start + 400) == (COMM_SUCCESS, 0)
        currents: list[int] = []
        late = 0  # replies past the SDK's timeout: the pseudo-terminal's kernel worker is time-shared
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            value, result, _ = bus.ph.read2ByteTxRx(bus.port, servo, present_current)
            if result == COMM_RX_TIMEOUT:
                late += 1
                continue
            assert result == COMM_SUCCESS
            currents.append(value - 65536 if value >= 32768 else value)
            time.sleep(0.02)
        assert len(currents) >= 20 and late <= len(currents) // 10, (late, len(currents))
        st = sim.status()
        assert 50 <= max(abs(c) for c in currents[-20:]) <= 63, (
            currents[-20:],
            st["servos"][servo - 1],
            st["q_rad"][servo - 1],
        )  # pressing at the limit
    finally:
        sim.inject("remove_object", device=servo)
        bus.ph.write1ByteTxRx(bus.port, servo, TORQUE_ENABLE, 0)
        bus.ph.write2ByteTxRx(bus.port, servo, current_limit, 1193)
        bus.ph.write1ByteTxRx(bus.port, servo, operating_mode, 3)


def test_a_usb_adapters_latency_timer_holds_every_short_reply(workdir: Path) -> None:
    """`--latency-timer-ms 16` (an FTDI adapter as it comes): a ping's 14-byte reply reaches the
    stock SDK no sooner than 16 ms after it left the servo; the dxl_cycle benchmark shows what
    that costs a loop."""
    d = workdir / "latency"
    d.mkdir(exist_ok=True)
    sim = DxlSimProcess(CONFIG, "--port", str(d / "ttyDXL"), "--latency-timer-ms", "16")
    try:
        b = Bus(sim.port, 4_000_000)
        try:
            times = []
            for _ in range(5):
                t0 = time.perf_counter()
                _, result, _ = b.ph.ping(b.port, 1)
                times.append((time.perf_counter() - t0) * 1e3)
                assert result == COMM_SUCCESS
        finally:
            b.close()
    finally:
        sim.stop()
    assert min(times) >= 16.0 and statistics.median(times) < 200.0, times


def test_a_servo_with_firmware_before_45_answers_sync_read_but_not_fast_sync_read(workdir: Path) -> None:
    """`--firmware 3=44`: servo 3 reports firmware 44 (ping, Firmware Version(6)) and, as a
    servo that does not know the instruction, is silent to a Fast Sync Read: the one packet
    stops where its part should be. A plain Sync Read gets all six."""
    d = workdir / "firmware"
    d.mkdir(exist_ok=True)
    sim = DxlSimProcess(CONFIG, "--port", str(d / "ttyDXL"), "--firmware", "3=44")
    try:
        b = Bus(sim.port, 4_000_000)
        try:
            assert b.ph.read1ByteTxRx(b.port, 3, 6)[:2] == (44, COMM_SUCCESS)
            assert b.ph.read1ByteTxRx(b.port, 2, 6)[:2] == (46, COMM_SUCCESS)
            read = GroupSyncRead(b.port, b.ph, 126, 10)
            for i in IDS:
                assert read.addParam(i)
            assert read.fastSyncRead() != COMM_SUCCESS
            assert read.txRxPacket() == COMM_SUCCESS
        finally:
            b.close()
    finally:
        sim.stop()
