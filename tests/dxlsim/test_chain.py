"""The chain in simulated time (no process, no sleep): control table rules, the servos' loops
on the arm's dynamics, hardware errors. Packets go through `Chain.handle` as bytes."""

from __future__ import annotations

import pytest

from orccadd.config.robot import read_robot_config
from orccadd.dxlsim import table as T
from orccadd.dxlsim.chain import Chain
from orccadd.dxlsim.protocol import ALERT, BROADCAST_ID, Error, Instruction, PacketReader, instruction_packet
from orccadd.dxlsim.servo import BOOT_TIME_S
from orccadd.dxlsim.settings import read_chain_settings
from tests.conftest import ROOT

CONFIG = ROOT / "configs" / "robots" / "dxl-6axis-sim.toml"
TICKS_PER_RAD = 4096 / 6.283185307179586


class Rig:
    def __init__(self) -> None:
        cfg = read_robot_config(CONFIG)
        self.chain = Chain(cfg, read_chain_settings(cfg))
        self.t = 0.0
        self.chain.start(self.t)

    def run(self, seconds: float) -> None:
        self.t += seconds
        self.chain.advance_to(self.t)

    def send(
        self, dxl_id: int, inst: int, params: bytes = b"", damaged: bool = False
    ) -> list[tuple[int, int, bytes]]:
        """(id, error byte, params) of every status packet the instruction earns."""
        raw = bytearray(instruction_packet(dxl_id, inst, params))
        raw[-1] ^= 0x01 if damaged else 0x00
        (packet,) = PacketReader().feed(bytes(raw))
        replies = []
        for reply in self.chain.handle(packet, self.t):
            data = reply.data
            replies.append((data[4], data[8], data[9:-2]))
        return replies

    def write(self, dxl_id: int, item: T.Item, value: int) -> int:
        ((_, error, _),) = self.send(dxl_id, Instruction.WRITE, _addr(item) + T.encode(item, value))
        return error

    def read(self, dxl_id: int, item: T.Item) -> int:
        ((_, _, data),) = self.send(dxl_id, Instruction.READ, _addr(item) + item.size.to_bytes(2, "little"))
        return int.from_bytes(data, "little", signed=item.signed)


def _addr(item: T.Item) -> bytes:
    return item.address.to_bytes(2, "little")


@pytest.fixture
def rig() -> Rig:
    return Rig()


def test_ping_answers_each_model_number_and_broadcast_ping_answers_in_id_order(rig: Rig) -> None:
    ((dxl_id, error, data),) = rig.send(2, Instruction.PING)
    assert (dxl_id, error, data) == (2, 0, bytes((0x60, 0x04, 46)))  # 1120: XM540-W270, firmware 46
    assert [r[0] for r in rig.send(BROADCAST_ID, Instruction.PING)] == [1, 2, 3, 4, 5, 6]
    models = [int.from_bytes(r[2][:2], "little") for r in rig.send(BROADCAST_ID, Instruction.PING)]
    assert models == [1120, 1120, 1120, 1020, 1020, 1020]


def test_access_rules_of_the_control_table(rig: Rig) -> None:
    assert rig.write(1, T.OPERATING_MODE, 1) == Error.NONE  # EEPROM, torque off
    assert rig.write(1, T.OPERATING_MODE, 2) == Error.DATA_RANGE  # no mode 2
    assert rig.write(1, T.OPERATING_MODE, 3) == Error.NONE
    assert rig.write(1, T.TORQUE_ENABLE, 1) == Error.NONE
    assert rig.write(1, T.OPERATING_MODE, 1) == Error.ACCESS  # EEPROM locked while torque is on
    assert rig.write(1, T.PRESENT_POSITION, 0) == Error.ACCESS  # read-only
    assert rig.write(1, T.GOAL_POSITION, 5000) == Error.DATA_LIMIT  # beyond Max Position Limit(48)
    assert rig.write(1, T.GOAL_VELOCITY, 2000) == Error.DATA_RANGE
    ((_, error, _),) = rig.send(1, Instruction.WRITE, _addr(T.GOAL_POSITION) + b"\x00\x08")  # 2 of 4 bytes
    assert error == Error.DATA_LENGTH
    ((_, error, _),) = rig.send(1, Instruction.WRITE, (14).to_bytes(2, "little") + b"\x00")  # no item there
    assert error == Error.ACCESS
    ((_, error, data),) = rig.send(1, Instruction.READ, bytes((0, 0, 148, 0)))
    assert error == 0 and len(data) == 148 and data[14:20] == bytes(6)  # gaps read as 0
    ((_, error, _),) = rig.send(1, Instruction.READ, bytes((140, 0, 16, 0)))
    assert error == Error.ACCESS  # past the simulated table
    ((_, error, _),) = rig.send(1, 0x42)
    assert error == Error.INSTRUCTION
    ((_, error, _),) = rig.send(1, Instruction.WRITE, _addr(T.LED) + b"\x01", damaged=True)
    assert error == Error.CRC and rig.read(1, T.LED) == 0


def test_status_return_level_and_reg_write_action(rig: Rig) -> None:
    assert rig.write(3, T.STATUS_RETURN_LEVEL, 1) == Error.NONE
    assert rig.send(3, Instruction.WRITE, _addr(T.LED) + b"\x01") == []  # level 1: reads only
    assert rig.read(3, T.LED) == 1
    assert rig.send(BROADCAST_ID, Instruction.WRITE, _addr(T.LED) + b"\x00") == []  # broadcast: no status
    assert rig.read(3, T.LED) == 0
    ((_, error, _),) = rig.send(2, Instruction.ACTION)
    assert error == Error.INSTRUCTION  # action without reg write
    rig.send(2, Instruction.REG_WRITE, _addr(T.LED) + b"\x01")
    assert (rig.read(2, T.LED), rig.read(2, T.REGISTERED_INSTRUCTION)) == (0, 1)
    assert rig.send(BROADCAST_ID, Instruction.ACTION) == []
    assert (rig.read(2, T.LED), rig.read(2, T.REGISTERED_INSTRUCTION)) == (1, 0)


def test_unpowered_arm_rests_at_home_and_the_position_loop_moves_it(rig: Rig) -> None:
    rig.run(1.0)
    start = [rig.read(i, T.PRESENT_POSITION) for i in range(1, 7)]
    assert all(abs(a - b) <= 1 for a, b in zip(start, [2048, 1944, 1129, 2048, 2113, 2048], strict=True))
    for i, p in enumerate(start, 1):
        rig.write(i, T.GOAL_POSITION, p)
        rig.write(i, T.TORQUE_ENABLE, 1)
        rig.write(i, T.GOAL_POSITION, p + 300)
    rig.run(2.0)
    for i, p in enumerate(start, 1):
        error = rig.read(i, T.PRESENT_POSITION) - (p + 300)
        assert abs(error) < 80, (i, error)  # P only (factory gains): gravity leaves an offset
        assert rig.read(i, T.MOVING) == 0
    assert abs(rig.chain.arm.q[0] - 300 / TICKS_PER_RAD) < 0.01


def test_profile_velocity_limits_the_speed(rig: Rig) -> None:
    p = rig.read(1, T.PRESENT_POSITION)
    rig.write(1, T.GOAL_POSITION, p)
    rig.write(1, T.PROFILE_VELOCITY, 20)  # 20 × 0.229 rpm = 0.48 rad/s
    rig.write(1, T.PROFILE_ACCELERATION, 10)
    rig.write(1, T.TORQUE_ENABLE, 1)
    rig.write(1, T.GOAL_POSITION, p + 600)
    rig.run(0.5)
    assert rig.read(1, T.MOVING_STATUS) & 0x32 == 0x32  # trapezoidal profile, ongoing
    assert 15 <= rig.read(1, T.VELOCITY_TRAJECTORY) <= 20
    assert 10 <= rig.read(1, T.PRESENT_VELOCITY) <= 25
    rig.run(2.5)
    assert rig.read(1, T.MOVING_STATUS) & 0x03 == 0x01  # in position
    assert abs(rig.read(1, T.PRESENT_POSITION) - (p + 600)) < 20


def test_velocity_and_current_modes(rig: Rig) -> None:
    rig.write(1, T.OPERATING_MODE, 1)
    rig.write(1, T.TORQUE_ENABLE, 1)
    rig.write(1, T.GOAL_VELOCITY, 50)
    rig.run(1.5)
    assert abs(rig.read(1, T.PRESENT_VELOCITY) - 50) <= 5
    rig.write(6, T.OPERATING_MODE, 0)
    rig.write(6, T.TORQUE_ENABLE, 1)
    rig.write(6, T.GOAL_CURRENT, -100)
    rig.run(0.01)
    assert abs(rig.read(6, T.PRESENT_CURRENT) + 100) <= 5  # the current loop holds it
    rig.run(0.3)
    assert rig.read(6, T.PRESENT_VELOCITY) < -20  # the wrist turns the way it pushes
    assert -100 < rig.read(6, T.PRESENT_CURRENT) < 0  # until the PWM runs out near no-load speed


def test_stalling_on_the_hard_stop_is_an_overload_that_only_a_reboot_clears(rig: Rig) -> None:
    rig.write(2, T.GOAL_POSITION, rig.read(2, T.PRESENT_POSITION))
    rig.write(2, T.TORQUE_ENABLE, 1)
    rig.write(2, T.GOAL_POSITION, 3600)  # past the shoulder's mechanical stop (1.99 rad ~ 3345)
    rig.run(0.8)
    assert rig.read(2, T.HARDWARE_ERROR_STATUS) == 0
    rig.run(1.5)
    ((_, error, data),) = rig.send(2, Instruction.READ, _addr(T.HARDWARE_ERROR_STATUS) + b"\x01\x00")
    assert (error, data) == (ALERT, b"\x20")  # overload; the alert bit is in every status packet
    assert rig.read(2, T.TORQUE_ENABLE) == 0
    assert rig.write(2, T.TORQUE_ENABLE, 1) == ALERT | Error.RESULT_FAIL
    ((_, error, _),) = rig.send(2, Instruction.REBOOT)
    assert error == ALERT
    assert rig.send(2, Instruction.PING) == []  # booting
    rig.run(BOOT_TIME_S + 0.01)
    ((_, error, _),) = rig.send(2, Instruction.PING)
    assert error == 0 and rig.read(2, T.HARDWARE_ERROR_STATUS) == 0


def test_bus_watchdog_stops_the_servo_and_makes_goals_read_only(rig: Rig) -> None:
    rig.write(1, T.OPERATING_MODE, 1)
    rig.write(1, T.TORQUE_ENABLE, 1)
    rig.write(1, T.BUS_WATCHDOG, 5)  # 100 ms
    rig.write(1, T.GOAL_VELOCITY, 40)
    rig.run(0.09)
    assert rig.read(1, T.BUS_WATCHDOG) == 5
    rig.run(0.5)
    assert rig.read(1, T.BUS_WATCHDOG) == -1
    assert abs(rig.read(1, T.PRESENT_VELOCITY)) <= 5
    assert rig.write(1, T.GOAL_VELOCITY, 10) == Error.DATA_RANGE
    assert rig.write(1, T.BUS_WATCHDOG, 0) == Error.NONE
    assert rig.write(1, T.GOAL_VELOCITY, 10) == Error.NONE


def test_factory_reset_keeps_what_its_option_says(rig: Rig) -> None:
    rig.write(4, T.RETURN_DELAY_TIME, 0)
    rig.write(4, T.OPERATING_MODE, 4)
    ((_, error, _),) = rig.send(4, Instruction.FACTORY_RESET, b"\x02")  # all but ID and baud rate
    assert error == 0
    rig.run(BOOT_TIME_S + 0.01)
    kept = rig.read(4, T.RETURN_DELAY_TIME), rig.read(4, T.OPERATING_MODE), rig.read(4, T.BAUD_RATE)
    assert kept == (250, 3, 6)
    assert rig.send(BROADCAST_ID, Instruction.FACTORY_RESET, b"\xff") == []  # never by broadcast
    ((_, error, _),) = rig.send(5, Instruction.FACTORY_RESET, b"\x01")  # resets the baud rate
    rig.run(BOOT_TIME_S + 0.01)
    assert rig.send(5, Instruction.PING) == []  # now at 57,600 bit/s: deaf at 4 Mbit/s
