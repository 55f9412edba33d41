"""Clocks for the executor: time is injected, never read from a global.

`WallClock` sleeps to absolute CLOCK_MONOTONIC deadlines with `clock_nanosleep(TIMER_ABSTIME)`
(so sleeping never drifts), optionally waking `spin_margin_s` early and spinning to the
deadline, which trims the scheduler's wake-up tail at the cost of CPU. `SimClock` jumps to each
deadline at once: tests and simulations run as fast as the CPU allows and deterministically.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import time
from abc import ABC, abstractmethod
from collections.abc import Callable

CLOCK_MONOTONIC = 1
TIMER_ABSTIME = 1


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class Clock(ABC):
    """Monotonic time in seconds, and sleeping to an absolute time."""

    @abstractmethod
    def now_ns(self) -> int:
        """Current time in nanoseconds on this clock's time base."""

    @abstractmethod
    def sleep_until_ns(self, deadline_ns: int) -> None:
        """Return at (or just after) `deadline_ns`. Never returns early."""

    def now_s(self) -> float:
        return self.now_ns() * 1e-9

    def wait_release_ns(self, deadline_ns: int) -> int:
        """Block until the next tick is released; its release time. Our own clocks release at
        the deadline; a device-paced clock when the device's cycle arrives."""
        self.sleep_until_ns(deadline_ns)
        return deadline_ns


class WallClock(Clock):
    """CLOCK_MONOTONIC with absolute sleeps; `spin_margin_s` > 0 sleeps then spins."""

    def __init__(self, spin_margin_s: float = 0.0) -> None:
        self.spin_margin_ns = int(spin_margin_s * 1e9)
        libc_name = ctypes.util.find_library("c") or "libc.so.6"
        self._libc = ctypes.CDLL(libc_name, use_errno=True)
        self._nanosleep = self._libc.clock_nanosleep
        self._nanosleep.argtypes = [
            ctypes.c_int,
            ctypes.c_int,
            ctypes.POINTER(_Timespec),
            ctypes.c_void_p,
        ]
        self._nanosleep.restype = ctypes.c_int
        self._ts = _Timespec()
        self._ts_ref = ctypes.byref(self._ts)

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until_ns(self, deadline_ns: int) -> None:
        wake = deadline_ns - self.spin_margin_ns
        ts = self._ts
        ts.tv_sec, ts.tv_nsec = divmod(wake, 1_000_000_000)
        while self._nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, self._ts_ref, None) == 4:  # EINTR
            pass
        if self.spin_margin_ns:
            now = time.monotonic_ns
            while now() < deadline_ns:
                pass


class DevicePacedClock(Clock):
    """The device's cycle releases each tick: `wait_for_cycle(timeout_s)` blocks until the
    device's next packet and returns its arrival time (CLOCK_MONOTONIC ns), or -1 on timeout.

    A cycle that has not come `stall_periods` periods after it was due releases the tick anyway
    (at the timeout), so the loop runs and the resource reports the stalled stream itself.
    """

    def __init__(
        self, wait_for_cycle: Callable[[float], int], period_s: float, stall_periods: float = 3.0
    ) -> None:
        self.wait_for_cycle = wait_for_cycle
        self.period_ns = int(round(period_s * 1e9))
        self.stall_ns = int(stall_periods * self.period_ns)

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until_ns(self, deadline_ns: int) -> None:
        while time.monotonic_ns() < deadline_ns:
            time.sleep(max(0.0, (deadline_ns - time.monotonic_ns()) * 1e-9))

    def wait_release_ns(self, deadline_ns: int) -> int:
        timeout_ns = max(0, deadline_ns + self.stall_ns - time.monotonic_ns())
        arrived = self.wait_for_cycle(timeout_ns * 1e-9)
        return arrived if arrived >= 0 else time.monotonic_ns()


class SimClock(Clock):
    """Simulated time: `sleep_until_ns` jumps there. Deterministic; starts at `start_s`."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now_ns = int(round(start_s * 1e9))

    def now_ns(self) -> int:
        return self._now_ns

    def sleep_until_ns(self, deadline_ns: int) -> None:
        if deadline_ns > self._now_ns:
            self._now_ns = deadline_ns

    def advance(self, dt_s: float) -> None:
        """Let time pass without a deadline (e.g. to simulate a slow tick in tests)."""
        self._now_ns += int(round(dt_s * 1e9))
