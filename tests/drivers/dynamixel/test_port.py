"""The port under the SDK: the USB adapter's latency timer (read from sysfs for a usb-serial tty,
skipped for anything else, a period it cannot meet refused with the fix), the cycle's deadline,
and a late reply dropped before the next request."""

from __future__ import annotations

import os
import threading
import time
import tty
from pathlib import Path

import pytest

from orccadd.drivers.dynamixel.port import BlockingPort, check_latency, latency_timer_s
from orccadd.errors import ResourceError


def adapter(tmp_path: Path, latency_ms: int) -> tuple[Path, Path]:
    """A fake /dev/ttyUSB0 behind a by-id link, and its sysfs latency_timer."""
    dev = tmp_path / "dev"
    dev.mkdir()
    (dev / "ttyUSB0").touch()
    link = dev / "usb-FTDI_USB__-__Serial_Converter-if00-port0"
    link.symlink_to(dev / "ttyUSB0")
    sysfs = tmp_path / "sys"
    (sysfs / "ttyUSB0").mkdir(parents=True)
    (sysfs / "ttyUSB0" / "latency_timer").write_text(f"{latency_ms}\n")
    return link, sysfs


@pytest.mark.parametrize("period_s", [0.005, 0.05])
def test_the_16_ms_default_is_refused_naming_the_file_and_the_udev_rule(
    tmp_path: Path, period_s: float
) -> None:
    link, sysfs = adapter(tmp_path, 16)
    assert latency_timer_s(str(link), sysfs) == pytest.approx(0.016)
    with pytest.raises(ResourceError) as e:
        check_latency(str(link), period_s, 0.0004, sysfs)  # above 1 ms: refused whatever the period
    msg = str(e.value)
    assert f"the USB adapter's latency timer ({sysfs}/ttyUSB0/latency_timer) is 16 ms" in msg
    assert f"echo 1 | sudo tee {sysfs}/ttyUSB0/latency_timer" in msg
    assert "60-orccadd-dynamixel.rules" in msg and "set_latency_timer = true" in msg


def test_one_ms_passes(tmp_path: Path) -> None:
    link, sysfs = adapter(tmp_path, 1)
    assert check_latency(str(link), 0.005, 0.0004, sysfs) == pytest.approx(0.001)


def test_one_ms_that_does_not_fit_the_period_is_refused(tmp_path: Path) -> None:
    link, sysfs = adapter(tmp_path, 1)
    with pytest.raises(ResourceError, match="cannot meet control_period_s = 0.0012"):
        check_latency(str(link), 0.0012, 0.0004, sysfs)


def test_set_latency_timer_writes_1_ms(tmp_path: Path) -> None:
    link, sysfs = adapter(tmp_path, 16)
    assert check_latency(str(link), 0.005, 0.0004, sysfs, set_it=True) == pytest.approx(0.001)
    assert (sysfs / "ttyUSB0" / "latency_timer").read_text().strip() == "1"


def test_set_latency_timer_that_cannot_write_says_what_to_do(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    link, sysfs = adapter(tmp_path, 16)

    def refused(self: Path, *args: object, **kwargs: object) -> int:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "write_text", refused)  # as sysfs answers a user without root
    with pytest.raises(ResourceError, match=r"cannot write 1 ms to .*Permission denied.*udev rule"):
        check_latency(str(link), 0.005, 0.0004, sysfs, set_it=True)


def test_a_latency_timer_that_cannot_be_read_is_an_error_naming_it(tmp_path: Path) -> None:
    link, sysfs = adapter(tmp_path, 1)
    (sysfs / "ttyUSB0" / "latency_timer").write_text("garbage\n")
    with pytest.raises(ResourceError, match=f"cannot read the USB adapter's latency timer {sysfs}/ttyUSB0"):
        check_latency(str(link), 0.005, 0.0004, sysfs)


def test_a_pseudo_terminal_has_no_latency_timer(tmp_path: Path) -> None:
    master, slave = os.openpty()
    try:
        assert latency_timer_s(os.ttyname(slave)) is None
        assert check_latency(os.ttyname(slave), 0.001, 0.0009) == 0.0
    finally:
        os.close(master)
        os.close(slave)


def test_a_late_reply_is_dropped_not_read_as_the_next_requests() -> None:
    """A reply that comes after its read timed out (here 2 ms later, in pieces: within another
    `read_timeout_s`) is waited out and dropped before the next request, and the wait ends once
    the line is quiet (a busy-wait-free bound: the margin for its first byte). The margins are
    wide here (9600 baud: a quiet line is 17 ms of silence; 0.2 s for the first byte) so that a
    busy machine's late thread cannot split the reply across them."""
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        port = BlockingPort(os.ttyname(slave), read_timeout_s=0.2)
        port.baudrate = 9600
        assert port.openPort()
        late = bytes([0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x08, 0x00, 0x55, 0x00, 0x11, 0x22, 0x33, 0x44])

        def answer_late() -> None:
            time.sleep(0.002)
            os.write(master, late[:6])
            time.sleep(0.0001)
            os.write(master, late[6:])

        writer = threading.Thread(target=answer_late)
        writer.start()
        t0 = time.monotonic()
        dropped = port.drop_late_reply()
        writer.join()
        assert dropped == len(late) and port.ser.in_waiting == 0
        assert time.monotonic() - t0 < 2.0  # ended on a quiet line, not at some later timeout
        t0 = time.monotonic()
        assert port.drop_late_reply() == 0 and time.monotonic() - t0 < 2.0  # nothing late: one margin
        port.setBaudRate(4_000_000)
        assert port.deadline_s(10, 14) == pytest.approx(24 * 10 / 4_000_000 + 0.2)
        port.closePort()
    finally:
        os.close(master)
        os.close(slave)
