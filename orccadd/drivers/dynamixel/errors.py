"""What the servos and the SDK report, by name: hardware error bits, status packet errors,
communication results.

Hardware Error Status(70) (e-Manual): bit 0 input voltage, 2 overheating, 3 motor encoder,
4 electrical shock, 5 overload; a set bit has switched the torque off and stays until a reboot.
Every status packet's error byte carries the alert bit (7) while one is set, and an error number
in bits 0-6 for the instruction itself (Protocol 2.0, Status Packet).
"""

from __future__ import annotations

from dynamixel_sdk import (
    COMM_NOT_AVAILABLE,
    COMM_PORT_BUSY,
    COMM_RX_CORRUPT,
    COMM_RX_FAIL,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    COMM_TX_ERROR,
    COMM_TX_FAIL,
)

HARDWARE_ERRORS: dict[int, str] = {
    0: "input voltage",
    2: "overheating",
    3: "motor encoder",
    4: "electrical shock",
    5: "overload",
}
ALERT = 0x80

PACKET_ERRORS: dict[int, str] = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}

COMM_RESULTS: dict[int, str] = {
    COMM_SUCCESS: "success",
    COMM_PORT_BUSY: "port busy",
    COMM_TX_FAIL: "transmit failed",
    COMM_RX_FAIL: "receive failed",
    COMM_TX_ERROR: "bad instruction packet",
    COMM_RX_TIMEOUT: "no status packet (timeout)",
    COMM_RX_CORRUPT: "damaged or incomplete status packet",
    COMM_NOT_AVAILABLE: "not available",
}


def hardware_error_text(bits: int) -> str:
    """`overload (bit 5)`, `overheating (bit 2), overload (bit 5)`; unknown bits by number."""
    names = [f"{HARDWARE_ERRORS.get(b, 'unknown error')} (bit {b})" for b in range(8) if bits >> b & 1]
    return ", ".join(names) or "none"


def packet_error_text(error: int) -> str:
    """The error byte of a status packet: its error number by name, and the alert bit."""
    number = error & 0x7F
    parts = [PACKET_ERRORS.get(number, f"error {number}")] if number else []
    if error & ALERT:
        parts.append("hardware error latched (alert)")
    return ", ".join(parts) or "none"


def comm_text(result: int) -> str:
    return COMM_RESULTS.get(result, f"result {result}")
