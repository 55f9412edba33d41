"""The USB adapter's latency timer: read from sysfs for a usb-serial tty, skipped for anything
else (a pseudo-terminal), and a period it cannot meet refused with the fix."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from orccadd.drivers.dynamixel.port import check_latency, latency_timer_s
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


def test_the_16_ms_default_cannot_meet_a_5_ms_period(tmp_path: Path) -> None:
    link, sysfs = adapter(tmp_path, 16)
    assert latency_timer_s(str(link), sysfs) == pytest.approx(0.016)
    with pytest.raises(ResourceError) as e:
        check_latency(str(link), 0.005, 0.0004, sysfs)
    msg = str(e.value)
    assert "the USB adapter's latency timer is 16 ms" in msg
    assert f"echo 1 | sudo tee {sysfs}/ttyUSB0/latency_timer" in msg


def test_one_ms_passes(tmp_path: Path) -> None:
    link, sysfs = adapter(tmp_path, 1)
    assert check_latency(str(link), 0.005, 0.0004, sysfs) == pytest.approx(0.001)


def test_a_pseudo_terminal_has_no_latency_timer(tmp_path: Path) -> None:
    master, slave = os.openpty()
    try:
        assert latency_timer_s(os.ttyname(slave)) is None
        assert check_latency(os.ttyname(slave), 0.001, 0.0009) == 0.0
    finally:
        os.close(master)
        os.close(slave)
