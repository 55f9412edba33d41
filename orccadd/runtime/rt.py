"""Real-time setup of the calling thread: SCHED_FIFO, locked memory, frozen garbage collector,
and a PM QoS request that keeps the CPUs out of deep idle states.

The last one matters as much as the priority: a CPU (or a virtual CPU) that halts between two
ticks takes tens of microseconds to milliseconds to wake up (a virtual one: up to several ms). As
`cyclictest` does, we write 0 to `/dev/cpu_dma_latency` and hold it open for as long as the
loop runs (the kernel drops the request when the file is closed). Measured on this project's
2-core VM, an empty 1 kHz loop: wake-up p99 2.3 ms without it, 65 µs with it.

Each step is tried and reported; where the system refuses (no privilege, no RT kernel
limits) the loop still runs, with a clear warning saying what is missing and how to grant it.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import struct
from dataclasses import dataclass, field

# `ORCCADD_SCHED_FIFO=off` in the environment: every orccadd process (a daemon's loops and
# automaton, a simulated device, a bus hub) runs time-shared, locked memory and the rest as
# configured. For a machine where orccadd must not take the CPUs from everything else: a CI
# runner checking missions on the simulated arm, a shared workstation. Not for a robot.
FIFO_ENV = "ORCCADD_SCHED_FIFO"
MCL_CURRENT = 1
MCL_FUTURE = 2
CPU_DMA_LATENCY = "/dev/cpu_dma_latency"


@dataclass
class RealtimeReport:
    """What `enter_realtime` achieved."""

    sched_fifo_priority: int | None = None
    cpus: frozenset[int] | None = None
    memory_locked: bool = False
    gc_frozen: bool = False
    cpu_dma_latency_us: int | None = None  # the PM QoS request held, None: none
    _qos_fd: int | None = field(default=None, repr=False)
    warnings: list[str] = field(default_factory=list)

    def describe(self) -> str:
        fifo = f"SCHED_FIFO {self.sched_fifo_priority}" if self.sched_fifo_priority else "SCHED_OTHER"
        if self.cpus is not None:
            fifo += f" on CPU {','.join(str(c) for c in sorted(self.cpus))}"
        qos = "none" if self.cpu_dma_latency_us is None else f"{self.cpu_dma_latency_us} µs"
        return (
            f"{fifo}, memory {'locked' if self.memory_locked else 'not locked'}, "
            f"gc {'frozen' if self.gc_frozen else 'running'}, CPU wake-up latency request {qos}"
        )


def fifo_priority(priority: int) -> int:
    """`priority`, or 0 (time-shared) where the environment turns SCHED_FIFO off (`FIFO_ENV`)."""
    return 0 if os.environ.get(FIFO_ENV, "").strip().lower() in ("off", "0", "no", "false") else priority


def lock_memory_early() -> list[str]:
    """For a process whose devices run I/O threads: lock its memory (`mlockall`, current and
    future pages) and collect its garbage *before* they start. Done later, in `enter_realtime`,
    both stall those threads while they must keep a device's watchdog fed: `mlockall` holds the
    process's memory map while it brings every page in (a thread that faults waits), a full
    collection holds the interpreter (a Python I/O thread waits): a CANopen drive then missed our
    heartbeat at startup (EMCY 0x8130). Warnings, if refused."""
    rep = RealtimeReport()
    _lock_memory(rep)
    gc.collect()
    return rep.warnings


def _lock_memory(rep: RealtimeReport) -> None:
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0:
        rep.memory_locked = True
    else:
        err = ctypes.get_errno()
        rep.warnings.append(
            f"mlockall refused ({os.strerror(err)}): page faults may stall the loop; "
            "grant LimitMEMLOCK=infinity (systemd) / memlock (limits.conf)"
        )


def enter_realtime(
    priority: int = 80,
    lock_memory: bool = True,
    freeze_gc: bool = True,
    collect_gc: bool = True,
    cpus: set[int] | None = None,
    cpu_dma_latency_us: int | None = 0,
) -> RealtimeReport:
    """Make the calling thread real-time where permitted (optionally pinned to `cpus`). Not for a tick.

    `cpu_dma_latency_us` (None: leave the CPUs' idle states alone) is held until `leave_realtime`.
    After `lock_memory_early`, pass `lock_memory=False, collect_gc=False`: the memory is locked
    already (its future pages too), and what was collected before is all there was to collect but
    the startup's own garbage, frozen with the rest (a full collection now would stall the
    devices' threads).
    """
    rep = RealtimeReport()
    if cpu_dma_latency_us is not None:
        _request_cpu_latency(rep, cpu_dma_latency_us)
    if cpus:
        try:
            os.sched_setaffinity(0, cpus)
            rep.cpus = frozenset(cpus)
        except (OSError, ValueError) as e:
            rep.warnings.append(f"CPU affinity {sorted(cpus)} refused ({e}): the thread may migrate")
    # the memory locked and the garbage collected before the priority is raised: both take tens of
    # milliseconds of CPU (mlockall of a process with Pinocchio: 63 ms on this project's VM), which
    # at SCHED_FIFO would stall every lower real-time thread on that core, another resource's
    # loop among them
    if lock_memory:
        _lock_memory(rep)
    if freeze_gc:
        if collect_gc:
            gc.collect()
        gc.freeze()
        gc.disable()
        rep.gc_frozen = True
    if priority > 0 and not fifo_priority(priority):
        rep.warnings.append(f"SCHED_FIFO {priority} not asked for ({FIFO_ENV}=off): the loop is time-shared")
    elif priority > 0:
        try:
            # reset on fork: a process this thread starts (the command daemon, a plant) runs at
            # normal priority unless it asks for more, never above the loop by inheritance
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
            rep.sched_fifo_priority = priority
        except OSError as e:
            rep.warnings.append(
                f"SCHED_FIFO {priority} refused ({e.strerror or e}): the loop runs at normal "
                "priority; run as root or grant LimitRTPRIO (systemd) / rtprio (limits.conf)"
            )
    return rep


def realtime_device_process(priority: int, cpu: int | None = None) -> list[str]:
    """Every thread of this process at SCHED_FIFO `priority`, and every thread it starts from now
    on (inherited: no reset-on-fork here), for a simulated device: hardware answers whatever the
    host's load, so its simulator must not wait behind time-shared work. (`enter_realtime` is
    for one loop thread: the threads a loop's process starts later run at normal priority.)
    Its memory is locked too (a page fault in a reply's path delays it by milliseconds, as a real
    device's never is). With `cpu`, every thread on that core only (a device has its own
    processor; later threads inherit it). Returns the warnings; nothing is changed where the
    system refuses."""
    warnings = [] if cpu is None else _pin(_thread_ids(), cpu)
    if fifo_priority(priority) <= 0:
        return warnings
    rep = RealtimeReport(warnings=warnings)
    _lock_memory(rep)
    try:
        _fifo(_thread_ids(), priority)
    except OSError as e:
        rep.warnings.append(
            f"SCHED_FIFO {priority} refused ({e.strerror or e}): the simulator runs at normal "
            "priority and may answer late on a busy machine"
        )
    return rep.warnings


class ThreadsStartedHere:
    """`with ThreadsStartedHere(priority) as started:` puts the threads a library starts inside
    the block at SCHED_FIFO `priority` (`started.warnings` says where refused). For a device
    library's I/O threads, which a loop's reset-on-fork leaves time-shared, and which some set
    real-time only on a PREEMPT_RT kernel (ur_rtde reads /sys/kernel/realtime): on a busy host
    a time-shared receive thread starves and the loop sees its stream stall."""

    def __init__(self, priority: int) -> None:
        self.priority = fifo_priority(priority)
        self.warnings: list[str] = []
        self._before: set[int] = set()

    def __enter__(self) -> ThreadsStartedHere:
        self._before = _thread_ids()
        return self

    def __exit__(self, *exc: object) -> None:
        new = {t for t in _thread_ids() - self._before if _time_shared(t)}
        if self.priority <= 0 or not new:
            return
        try:
            _fifo(new, self.priority)
        except OSError as e:
            self.warnings.append(
                f"SCHED_FIFO {self.priority} refused for {len(new)} I/O thread(s) ({e.strerror or e}): "
                "they run at normal priority and may fall behind on a busy machine"
            )


def _pin(tids: set[int], cpu: int) -> list[str]:
    try:
        for tid in tids:
            os.sched_setaffinity(tid, {cpu})
    except (OSError, ValueError) as e:
        return [f"CPU {cpu} refused ({e}): the simulator's threads may run on any core"]
    return []


def _thread_ids() -> set[int]:
    return {int(t) for t in os.listdir("/proc/self/task")}


def _time_shared(tid: int) -> bool:
    try:
        return os.sched_getscheduler(tid) == os.SCHED_OTHER
    except ProcessLookupError:  # it has ended
        return False


def _fifo(tids: set[int], priority: int) -> None:
    param = os.sched_param(priority)
    for tid in tids:
        with contextlib.suppress(ProcessLookupError):  # a thread that just ended
            os.sched_setscheduler(tid, os.SCHED_FIFO, param)


def _request_cpu_latency(rep: RealtimeReport, latency_us: int) -> None:
    try:
        fd = os.open(CPU_DMA_LATENCY, os.O_WRONLY | os.O_CLOEXEC)
    except OSError as e:
        rep.warnings.append(
            f"{CPU_DMA_LATENCY} not writable ({e.strerror or e}): the CPUs may sleep between ticks "
            "and wake late and cold; run as root or grant write access to it"
        )
        return
    try:
        os.write(fd, struct.pack("=i", latency_us))
    except OSError as e:
        os.close(fd)
        rep.warnings.append(f"{CPU_DMA_LATENCY}: writing {latency_us} refused ({e.strerror or e})")
        return
    rep._qos_fd, rep.cpu_dma_latency_us = fd, latency_us


def leave_realtime(report: RealtimeReport) -> None:
    """Undo `enter_realtime` for the calling thread (back to SCHED_OTHER, gc on, PM QoS released)."""
    if report._qos_fd is not None:
        with contextlib.suppress(OSError):
            os.close(report._qos_fd)
        report._qos_fd = None
    if report.sched_fifo_priority:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    if report.gc_frozen:
        gc.enable()
        gc.unfreeze()
