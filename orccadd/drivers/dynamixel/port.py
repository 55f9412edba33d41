"""The serial port under the SDK: blocking reads, our timeouts, and the USB latency timer.

`dynamixel_sdk.PortHandler` opens the port with no read timeout and its `rxPacket` polls
`readPort` in a loop until the packet is complete or its timeout (at least 34 ms: twice a 16 ms
USB latency, plus 2 ms) passes: a busy loop that cost ~3 ms per transaction on a pseudo-terminal
here, and a timeout far beyond a control period. `BlockingPort` keeps the SDK's protocol code
(packets, CRC, stuffing, the group classes) and changes only the port under it:

- `readPort` waits in `select` until bytes arrive or the packet's deadline passes, then takes
  what is there (the SDK asks for exactly the bytes it still needs);
- a packet's deadline is the wire time of the request and of the expected reply at the baud
  rate, plus the adapter's latency and `read_timeout_s` (see `setPacketTimeout`);
- time is CLOCK_MONOTONIC (the SDK uses the wall clock);
- after a read that timed out, the rest of its late reply is waited out and dropped
  (`drop_late_reply`), so that it does not arrive in the next request's time and read as its
  reply (the SDK's `clearPort` drops only what is already there when the next request goes);
- a port whose device is gone (a USB adapter unplugged, the simulator's pseudo-terminal closed)
  is `lost`: its descriptor is always readable and reads end of file, or the calls fail with
  EIO, ENODEV, ENXIO, EBADF (`tcflush` with a `termios.error`, which is no OSError). The first
  such answer sets `lost` (in words); from then on nothing touches the descriptor, a write sends
  nothing (the SDK's transactions fail: COMM_TX_FAIL) and a read waits for nothing (its
  packet has timed out): no busy loop, no exception out of a tick. Only a new port (`open_port`
  again, by the backend's reset) works again.

So the chain may answer up to `read_timeout_s` (default 3 ms) later than the wire time of the
request and of its reply at the baud rate, plus the adapter's latency timer: a servo busy, a
loaded host, a USB adapter that holds bytes back. Later than that, the read is a timeout (counted
per servo whose part was missing); `comm_errors_in_a_row` failed reads in a row are CommLost.
`cycle_deadline_s` says what that deadline is for the cyclic read.

`latency_timer_s` reads an FTDI adapter's latency timer from sysfs; `check_latency` refuses one
above 1 ms (or writes 1 ms, by config) and a period it cannot meet, each with the fix.
"""

from __future__ import annotations

import errno
import os
import select
import termios
import time
from pathlib import Path

from dynamixel_sdk import PortHandler

from orccadd.errors import ResourceError

SYSFS_USB_SERIAL = Path("/sys/bus/usb-serial/devices")
MAX_LATENCY_S = 0.001  # what a control loop can live with (FTDI's default is 16 ms)
# the rule that sets 1 ms when an adapter is plugged (installed from the wheel: docs/install.md)
UDEV_RULE = "share/orccadd/udev/60-orccadd-dynamixel.rules (packaging/udev/ in a checkout)"
HUNG_UP = "hung up: end of file"  # readable, and a read returns nothing: the device is gone
LATE_REPLY_MAX_BYTES = 1024  # the SDK's longest status packet: `drop_late_reply` drops no more


def failure_text(e: BaseException) -> str:
    """An OSError's or a termios.error's errno in words: `EIO: Input/output error`."""
    code = getattr(e, "errno", None)
    if code is None and e.args and isinstance(e.args[0], int):
        code = e.args[0]  # termios.error(errno, text)
    if isinstance(code, int) and code in errno.errorcode:
        return f"{errno.errorcode[code]}: {os.strerror(code)}"
    return str(e) or type(e).__name__


class BlockingPort(PortHandler):  # type: ignore[misc]  # the SDK is untyped
    """`PortHandler` with blocking reads and deadlines from the wire time, and a device that is
    gone reported as `lost` instead of a busy loop or an exception (see the module)."""

    def __init__(self, port_name: str, read_timeout_s: float, latency_s: float = 0.0) -> None:
        super().__init__(port_name)
        self.latency_ms = latency_s * 1e3
        self.extra_ms = read_timeout_s * 1e3 + self.latency_ms
        self.last_tx_bytes = 0
        self.lost = ""  # why the port is gone, in words ("" while it works, until closed)
        self._fd = -1

    def setupPort(self, cflag_baud: int) -> bool:  # noqa: N802 - the SDK's name
        ok = bool(super().setupPort(cflag_baud))
        self._fd = self.ser.fileno()
        self.lost = ""  # a descriptor of its own now
        return ok

    def _gone(self, why: str) -> None:
        """The device answered as one that is gone (the rare path: words made once)."""
        if not self.lost:
            self.lost = why

    def closePort(self) -> None:  # noqa: N802
        """Close it (a port whose device is gone closes too; an error closing it is ignored).
        Closed, it is `lost` ("closed"): no call touches a descriptor number reused since."""
        try:
            super().closePort()
        except (OSError, termios.error) as e:
            self._gone(failure_text(e))
            self.is_open = False
        self._fd = -1
        self._gone("closed")

    def clearPort(self) -> None:  # noqa: N802
        """Drop what arrived before a request (tcflush); on a lost port, nothing."""
        if self.lost:
            return
        try:
            termios.tcflush(self._fd, termios.TCIFLUSH)
        except (OSError, termios.error) as e:  # termios.error is no OSError: EIO once hung up
            self._gone(failure_text(e))

    def writePort(self, packet: list[int]) -> int:  # noqa: N802
        """The packet in one write(2) (pyserial's own write waits in `select` first); the rest,
        if the driver took only part of it, through pyserial. Bytes written: 0 on a lost port."""
        if self.lost:
            return 0
        data = bytes(packet)
        self.last_tx_bytes = len(data)
        try:
            try:
                n = os.write(self._fd, data)
            except BlockingIOError:
                n = 0
            if n != len(data):
                n += int(self.ser.write(data[n:]))
        except OSError as e:  # EIO, ENODEV, ENXIO, EBADF; pyserial's SerialException too
            self._gone(failure_text(e))
            return 0
        return n

    def readPort(self, length: int) -> bytes:  # noqa: N802
        """What has arrived of the `length` bytes the SDK still needs, waiting for the first of
        them until the packet's deadline (bytes already there are taken even past it); b"" on a
        lost port (or one found lost now: readable, with nothing to read)."""
        if self.lost or length <= 0:
            return b""
        remaining_s = (self.packet_timeout - (self.getCurrentTime() - self.packet_start_time)) * 1e-3
        ready, _, _ = select.select((self._fd,), (), (), max(0.0, remaining_s))
        if not ready:
            return b""
        try:
            data = os.read(self._fd, length)
        except BlockingIOError:
            return b""
        except OSError as e:
            self._gone(failure_text(e))
            return b""
        if not data:  # readable, yet nothing: a hang-up (pyserial says the same, "disconnected")
            self._gone(HUNG_UP)
        return data

    def isPacketTimeout(self) -> bool:  # noqa: N802
        """The SDK's receive loop ends at once on a lost port (it would poll to its deadline)."""
        return bool(self.lost) or bool(super().isPacketTimeout())

    def drop_late_reply(self) -> int:
        """After a timeout: drop the late reply, if it comes within another `read_timeout_s` (and
        the adapter's latency), then whatever follows until the line has been quiet for the wire
        time of a few bytes, at most a status packet's worth of wire time and margins (a line
        that never goes quiet: noise). Bytes dropped (tick-safe: bounded by the port's margins;
        a port found lost ends it at once)."""
        quiet_s = max(0.0003, self.tx_time_per_byte * 16e-3)
        wait_s = self.extra_ms * 1e-3  # for its first byte
        end = time.monotonic() + wait_s + quiet_s + self.tx_time_per_byte * LATE_REPLY_MAX_BYTES * 1e-3
        dropped = 0
        while not self.lost:
            ready, _, _ = select.select((self._fd,), (), (), wait_s)
            if not ready:
                return dropped
            try:
                data = os.read(self._fd, 4096)
            except BlockingIOError:
                return dropped
            except OSError as e:
                self._gone(failure_text(e))
                return dropped
            if not data:
                self._gone(HUNG_UP)
                return dropped
            dropped += len(data)
            wait_s = min(quiet_s, end - time.monotonic())
            if wait_s <= 0.0:
                return dropped
        return dropped

    def deadline_s(self, request_bytes: int, reply_bytes: int) -> float:
        """How long a reply of `reply_bytes` to a request of `request_bytes` is waited for."""
        return float(self.tx_time_per_byte * (request_bytes + reply_bytes) + self.extra_ms) * 1e-3

    def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802
        """Deadline for a reply of `packet_length` bytes to the request just written."""
        self.packet_start_time = self.getCurrentTime()
        wire_ms = self.tx_time_per_byte * (packet_length + self.last_tx_bytes)
        self.packet_timeout = wire_ms + self.extra_ms

    def patient(self, timeout_s: float) -> _Patience:
        """`with port.patient(0.05):` transactions that may wait longer than the cycle's (a
        servo's first answer, one busy writing its EEPROM): lifecycle steps, never a tick."""
        return _Patience(self, timeout_s * 1e3 + self.latency_ms)

    def getCurrentTime(self) -> float:  # noqa: N802
        """Milliseconds on CLOCK_MONOTONIC."""
        return time.monotonic_ns() * 1e-6


class _Patience:
    def __init__(self, port: BlockingPort, extra_ms: float) -> None:
        self.port, self.extra_ms, self.saved_ms = port, extra_ms, port.extra_ms

    def __enter__(self) -> None:
        self.saved_ms = self.port.extra_ms
        self.port.extra_ms = max(self.extra_ms, self.saved_ms)

    def __exit__(self, *exc: object) -> None:
        self.port.extra_ms = self.saved_ms


def open_port(path: str, baud_bit_s: int, read_timeout_s: float, latency_s: float = 0.0) -> BlockingPort:
    """The port at `baud_bit_s`, or a `ResourceError` saying why not."""
    port = BlockingPort(path, read_timeout_s, latency_s)
    try:
        port.baudrate = baud_bit_s
        ok = port.openPort()
    except (OSError, ValueError) as e:  # serial.SerialException is an OSError
        raise ResourceError(f"cannot open the DYNAMIXEL port {path}: {e}") from None
    if not ok:
        raise ResourceError(f"cannot open the DYNAMIXEL port {path} at {baud_bit_s} bit/s")
    return port


def latency_timer_s(port_path: str, sysfs: Path = SYSFS_USB_SERIAL) -> float | None:
    """The USB-serial adapter's latency timer behind `port_path` (a link such as
    /dev/serial/by-id/... is followed), or None when the device is no USB-serial tty (a
    pseudo-terminal, a CDC-ACM board, a native UART). A timer that is there but cannot be read is
    a `ResourceError` naming the file."""
    f = _timer_file(port_path, sysfs)
    if not f.exists():
        return None
    try:
        return int(f.read_text().strip()) * 1e-3
    except (OSError, ValueError) as e:
        raise ResourceError(
            f"{port_path}: cannot read the USB adapter's latency timer {f} ({e}): it decides how late "
            "every reply comes; make it readable (it is world-readable unless changed)"
        ) from None


def check_latency(
    port_path: str, period_s: float, busy_s: float, sysfs: Path = SYSFS_USB_SERIAL, set_it: bool = False
) -> float:
    """The adapter's latency (0 when it has no latency timer). Above MAX_LATENCY_S it is written
    down to 1 ms where `set_it` (the config's `set_latency_timer`), else refused naming the file
    and the udev rule that fixes it; a latency that with the wire time `busy_s` does not fit in
    the period is refused too."""
    latency = latency_timer_s(port_path, sysfs)
    if latency is None:
        return 0.0
    f = _timer_file(port_path, sysfs)
    if latency > MAX_LATENCY_S and set_it:
        try:
            f.write_text("1\n")
        except OSError as e:
            raise ResourceError(
                f"{port_path}: set_latency_timer: cannot write 1 ms to {f} ({e.strerror or e}): run as "
                f"root, or install the udev rule {UDEV_RULE} (then re-plug the adapter)"
            ) from None
        latency = latency_timer_s(port_path, sysfs) or 0.0
    if latency > MAX_LATENCY_S:
        raise ResourceError(
            f"{port_path}: the USB adapter's latency timer ({f}) is {latency * 1e3:g} ms: it holds "
            f"every reply back that long, and a control loop needs 1 ms or less. Set it now: echo 1 | "
            f"sudo tee {f}; for good: install the udev rule {UDEV_RULE} and re-plug the adapter; or "
            "let orccadd write it at startup: set_latency_timer = true in [resource.settings] (root)"
        )
    if latency + busy_s > period_s:
        raise ResourceError(
            f"{port_path}: the USB adapter's latency timer is {latency * 1e3:g} ms: with the chain's "
            f"{busy_s * 1e3:.2g} ms of wire time it cannot meet control_period_s = {period_s:g}: "
            "lengthen the period"
        )
    return latency


def _timer_file(port_path: str, sysfs: Path) -> Path:
    return sysfs / Path(os.path.realpath(port_path)).name / "latency_timer"
