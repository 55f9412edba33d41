"""A port whose device is gone (`BlockingPort.lost`): a pseudo-terminal whose other end closes,
as the servo simulator killed or a USB adapter unplugged. Its descriptor is then always
readable, reads end of file, and write and tcflush fail with EIO (tcflush as a termios.error,
which is no OSError). It was: `drop_late_reply` looped for ever on the end of file (the control
thread spinning, holding the chain's lock), and the SDK's `clearPort` raised out of the tick.
Now the port is `lost`, in words, and nothing waits or raises. No timing is asserted: a hang
would be caught by the bounded waits of the checks (generous, for a loaded machine)."""

from __future__ import annotations

import os
import termios
import threading
import time
import tty
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from typing import Any, TypeVar

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_TX_FAIL, PacketHandler

from orccadd.drivers.dynamixel.port import HUNG_UP, BlockingPort, failure_text

BOUND_S = 20.0


@contextmanager
def pty_port(read_timeout_s: float = 0.003) -> Iterator[tuple[BlockingPort, int]]:
    """A BlockingPort on a pseudo-terminal at 4 Mbit/s, and the terminal's other end (the
    device's: the test closes it to make the device vanish)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    port = BlockingPort(os.ttyname(slave), read_timeout_s)
    port.baudrate = 4_000_000
    assert port.openPort()
    os.close(slave)  # the port has its own descriptor
    try:
        yield port, master
    finally:
        port.closePort()
        with suppress(OSError):
            os.close(master)


R = TypeVar("R")


def within(call: Callable[..., R], *args: Any) -> R:
    """`call(*args)` in a thread, its result, asserting that it returns within BOUND_S."""
    out: list[R] = []
    t = threading.Thread(target=lambda: out.append(call(*args)), daemon=True)
    t.start()
    t.join(BOUND_S)
    assert not t.is_alive(), f"{call} did not return within {BOUND_S:g} s"
    return out[0]


def test_a_vanished_device_is_lost_not_a_busy_loop_nor_an_exception() -> None:
    with pty_port() as (port, master):
        ph = PacketHandler(2.0)
        os.write(master, b"\x01")  # something arrived: the port works
        assert port.drop_late_reply() == 1 and not port.lost
        os.close(master)
        assert within(port.drop_late_reply) == 0  # it was a loop for ever on the end of file
        assert port.lost == HUNG_UP
        assert port.readPort(10) == b"" and port.writePort([0xFF] * 10) == 0
        port.clearPort()  # tcflush: EIO, a termios.error, not raised
        assert port.isPacketTimeout()
        _, result, _ = within(ph.ping, port, 1)
        assert result == COMM_TX_FAIL and not port.is_using  # nothing sent, the port not left busy


def test_a_device_vanishing_while_a_reply_is_awaited_ends_the_wait() -> None:
    """The device's end closed while the SDK waits for a reply (a long read timeout here: the
    wait ends by the hang-up, not at its deadline)."""
    with pty_port(read_timeout_s=BOUND_S * 2) as (port, master):
        ph = PacketHandler(2.0)
        closer = threading.Timer(0.05, os.close, (master,))
        closer.start()
        _, result, _ = within(ph.ping, port, 1)
        closer.join()
        assert result in (COMM_RX_TIMEOUT, COMM_TX_FAIL) and port.lost, (result, port.lost)


def test_the_first_failure_is_the_one_reported_in_words() -> None:
    with pty_port() as (port, master):
        os.close(master)
        assert port.writePort([0xFF, 0xFF, 0xFD]) == 0
        assert port.lost == "EIO: Input/output error", port.lost  # write(2) on a hung-up terminal
        port.readPort(4)
        assert port.lost == "EIO: Input/output error"  # the first answer kept


def test_a_line_that_never_goes_quiet_ends_the_drop_all_the_same() -> None:
    """A device that babbles without end (noise on a broken line): the drop of a late reply
    ends after about a status packet's worth of wire time, while the line still babbles."""
    with pty_port() as (port, master):
        babbling = threading.Event()
        babbling.set()

        def babble() -> None:
            while babbling.is_set():
                try:
                    os.write(master, b"\xaa" * 64)
                except BlockingIOError:  # the port's buffer full: it is not being read now
                    time.sleep(0.0002)

        os.set_blocking(master, False)
        writer = threading.Thread(target=babble, daemon=True)
        writer.start()
        try:
            dropped = within(port.drop_late_reply)
            assert writer.is_alive() and dropped > 0
            assert not port.lost
        finally:
            babbling.clear()
            writer.join(BOUND_S)


def test_failure_text_names_the_errno() -> None:
    assert failure_text(OSError(19, "No such device")) == "ENODEV: No such device"
    assert failure_text(termios.error(5, "Input/output error")) == "EIO: Input/output error"
    assert failure_text(OSError("write failed")) == "write failed"
