"""Hardware error bits, status packet errors and SDK results by name."""

from __future__ import annotations

from dynamixel_sdk import COMM_RX_CORRUPT, COMM_RX_TIMEOUT

from orccadd.drivers.dynamixel.errors import ALERT, comm_text, hardware_error_text, packet_error_text
from orccadd.dxlsim import servo as sim_servo


def test_hardware_error_bits_by_name_and_number() -> None:
    assert hardware_error_text(0x20) == "overload (bit 5)"
    assert hardware_error_text(0x04 | 0x20) == "overheating (bit 2), overload (bit 5)"
    assert hardware_error_text(0x01) == "input voltage (bit 0)"
    assert hardware_error_text(0x10) == "electrical shock (bit 4)"
    assert hardware_error_text(0x08) == "motor encoder (bit 3)"
    assert hardware_error_text(0x40) == "unknown error (bit 6)"
    assert hardware_error_text(0) == "none"


def test_the_bits_the_simulator_raises_decode_to_their_names() -> None:
    for bit, name in (
        (sim_servo.OVERLOAD, "overload"),
        (sim_servo.OVERHEATING, "overheating"),
        (sim_servo.VOLTAGE_ERROR, "input voltage"),
        (sim_servo.ELECTRICAL_SHOCK, "electrical shock"),
        (sim_servo.ENCODER, "motor encoder"),
    ):
        assert hardware_error_text(bit).startswith(name)


def test_status_packet_error_byte() -> None:
    assert packet_error_text(7) == "access error"
    assert packet_error_text(ALERT | 1) == "result fail, hardware error latched (alert)"
    assert packet_error_text(ALERT) == "hardware error latched (alert)"
    assert packet_error_text(0) == "none"


def test_sdk_results() -> None:
    assert comm_text(COMM_RX_TIMEOUT) == "no status packet (timeout)"
    assert comm_text(COMM_RX_CORRUPT) == "damaged or incomplete status packet"
    assert comm_text(-1234) == "result -1234"
