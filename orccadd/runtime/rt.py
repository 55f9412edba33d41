"""Real-time setup of the calling thread: SCHED_FIFO, locked memory, frozen garbage collector.

Each step is tried and reported; where the system refuses (no privilege, no RT kernel
limits) the loop still runs, with a clear warning saying what is missing and how to grant it.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
from dataclasses import dataclass, field

MCL_CURRENT = 1
MCL_FUTURE = 2


@dataclass
class RealtimeReport:
    """What `enter_realtime` achieved."""

    sched_fifo_priority: int | None = None
    cpus: frozenset[int] | None = None
    memory_locked: bool = False
    gc_frozen: bool = False
    warnings: list[str] = field(default_factory=list)

    def describe(self) -> str:
        fifo = f"SCHED_FIFO {self.sched_fifo_priority}" if self.sched_fifo_priority else "SCHED_OTHER"
        if self.cpus is not None:
            fifo += f" on CPU {','.join(str(c) for c in sorted(self.cpus))}"
        return (
            f"{fifo}, memory {'locked' if self.memory_locked else 'not locked'}, "
            f"gc {'frozen' if self.gc_frozen else 'running'}"
        )


def enter_realtime(
    priority: int = 80, lock_memory: bool = True, freeze_gc: bool = True, cpus: set[int] | None = None
) -> RealtimeReport:
    """Make the calling thread real-time where permitted (optionally pinned to `cpus`). Not for a tick."""
    rep = RealtimeReport()
    if cpus:
        try:
            os.sched_setaffinity(0, cpus)
            rep.cpus = frozenset(cpus)
        except (OSError, ValueError) as e:
            rep.warnings.append(f"CPU affinity {sorted(cpus)} refused ({e}): the thread may migrate")
    if priority > 0:
        try:
            # reset on fork: a process this thread starts (the command daemon, a plant) runs at
            # normal priority unless it asks for more, never above the loop by inheritance
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
            rep.sched_fifo_priority = priority
        except (PermissionError, OSError) as e:
            rep.warnings.append(
                f"SCHED_FIFO {priority} refused ({e.strerror or e}): the loop runs at normal "
                "priority; run as root or grant LimitRTPRIO (systemd) / rtprio (limits.conf)"
            )
    if lock_memory:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0:
            rep.memory_locked = True
        else:
            err = ctypes.get_errno()
            rep.warnings.append(
                f"mlockall refused ({os.strerror(err)}): page faults may stall the loop; "
                "grant LimitMEMLOCK=infinity (systemd) / memlock (limits.conf)"
            )
    if freeze_gc:
        gc.collect()
        gc.freeze()
        gc.disable()
        rep.gc_frozen = True
    return rep


def leave_realtime(report: RealtimeReport) -> None:
    """Undo `enter_realtime` for the calling thread (back to SCHED_OTHER, gc on)."""
    if report.sched_fifo_priority:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    if report.gc_frozen:
        gc.enable()
        gc.unfreeze()
