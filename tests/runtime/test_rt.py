"""Real-time setup: the PM QoS request that keeps CPUs out of deep idle is held, then released."""

from __future__ import annotations

import os
import struct
import subprocess
import sys

import pytest

from orccadd.runtime.rt import CPU_DMA_LATENCY, enter_realtime, leave_realtime


def test_cpu_latency_request_held_while_realtime_and_released_after() -> None:
    rep = enter_realtime(0, lock_memory=False, freeze_gc=False, cpu_dma_latency_us=0)
    try:
        if not os.access(CPU_DMA_LATENCY, os.W_OK):  # not root, or no PM QoS: said, not hidden
            assert rep.cpu_dma_latency_us is None
            assert any(CPU_DMA_LATENCY in w for w in rep.warnings)
            return
        assert rep.cpu_dma_latency_us == 0
        assert "CPU wake-up latency request 0 µs" in rep.describe()
        with open(CPU_DMA_LATENCY, "rb") as f:  # the kernel's aggregate of all requests
            assert struct.unpack("=i", f.read(4))[0] == 0
        fd = rep._qos_fd
        assert fd is not None
    finally:
        leave_realtime(rep)
    with pytest.raises(OSError):
        os.fstat(fd)  # closed: the kernel dropped our request


def test_no_cpu_latency_request_when_not_asked() -> None:
    rep = enter_realtime(0, lock_memory=False, freeze_gc=False, cpu_dma_latency_us=None)
    leave_realtime(rep)
    assert rep.cpu_dma_latency_us is None
    assert "request none" in rep.describe()


DEVICE_PROCESS = """
import os, threading
from orccadd.runtime.rt import realtime_device_process
before = threading.Event()
t1 = threading.Thread(target=before.wait)  # a thread started before (a bus's reader)
t1.start()
assert realtime_device_process(5) == []
seen = {}
def later():
    seen["later"] = os.sched_getscheduler(0)
t2 = threading.Thread(target=later)  # and one started after (the simulator's loop)
t2.start(); t2.join()
seen["before"] = os.sched_getscheduler(t1.native_id)
before.set(); t1.join()
locked_kb = next(int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmLck:"))
print(seen["before"] == os.SCHED_FIFO, seen["later"] == os.SCHED_FIFO, locked_kb > 0)
"""


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root (or RLIMIT_RTPRIO)")
def test_a_simulated_device_runs_every_thread_at_real_time_priority_with_its_memory_locked() -> None:
    # (enter_realtime's reset-on-fork left a simulator's later threads time-shared: a busy machine
    # starved them and the controller saw its drives go silent)
    r = subprocess.run([sys.executable, "-c", DEVICE_PROCESS], capture_output=True, text=True, timeout=60)
    assert r.stdout.split() == ["True", "True", "True"], r.stdout + r.stderr


DEVICE_ON_A_CORE = """
import os, threading
from orccadd.runtime.rt import realtime_device_process
before = threading.Event()
t1 = threading.Thread(target=before.wait)
t1.start()
warnings = realtime_device_process(0, cpu=0)  # time-shared, on core 0 only
seen = {}
t2 = threading.Thread(target=lambda: seen.update(later=os.sched_getaffinity(0)))
t2.start(); t2.join()
seen["before"] = os.sched_getaffinity(t1.native_id)
before.set(); t1.join()
print(warnings == [], seen["before"] == {0}, seen["later"] == {0}, os.sched_getaffinity(0) == {0})
"""


def test_a_simulated_device_may_have_a_core_of_its_own_for_every_thread() -> None:
    r = subprocess.run([sys.executable, "-c", DEVICE_ON_A_CORE], capture_output=True, text=True, timeout=60)
    assert r.stdout.split() == ["True"] * 4, r.stdout + r.stderr


LIBRARY_THREADS = """
import os, threading
from orccadd.runtime.rt import ThreadsStartedHere, enter_realtime
enter_realtime(6, lock_memory=False, freeze_gc=False, cpu_dma_latency_us=None)  # a loop's thread
old = threading.Event()
t0 = threading.Thread(target=old.wait)  # started before the block: left alone
t0.start()
go = threading.Event()
with ThreadsStartedHere(4) as started:
    t1 = threading.Thread(target=go.wait)  # a library's receive thread (reset-on-fork: time-shared)
    t1.start()
    was = os.sched_getscheduler(t1.native_id)
now = os.sched_getscheduler(t1.native_id), os.sched_getparam(t1.native_id).sched_priority
print(was == os.SCHED_OTHER, now == (os.SCHED_FIFO, 4), os.sched_getscheduler(t0.native_id) == os.SCHED_OTHER)
print(started.warnings)
go.set(); old.set(); t1.join(); t0.join()
"""


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root (or RLIMIT_RTPRIO)")
def test_threads_a_library_starts_in_the_block_run_at_its_priority_those_before_do_not() -> None:
    # (ur_rtde sets its receive threads real-time on a PREEMPT_RT kernel only: on another, beside
    # a busy process, they starved and the loop saw the controller's stream stall for 56 ms)
    r = subprocess.run([sys.executable, "-c", LIBRARY_THREADS], capture_output=True, text=True, timeout=60)
    assert r.stdout.split("\n")[:2] == ["True True True", "[]"], r.stdout + r.stderr


FIFO_OFF = """
import os, threading
from orccadd.runtime.rt import ThreadsStartedHere, enter_realtime, realtime_device_process
rep = enter_realtime(6, lock_memory=False, freeze_gc=False, cpu_dma_latency_us=None)
device = realtime_device_process(5)
go = threading.Event()
with ThreadsStartedHere(4) as started:
    t1 = threading.Thread(target=go.wait)
    t1.start()
print(rep.sched_fifo_priority, os.sched_getscheduler(0) == os.SCHED_OTHER, device == [])
print(os.sched_getscheduler(t1.native_id) == os.SCHED_OTHER, started.warnings == [])
print(rep.warnings)
go.set(); t1.join()
"""


def test_the_environment_may_turn_sched_fifo_off_for_every_process() -> None:
    env = {**os.environ, "ORCCADD_SCHED_FIFO": "off"}
    r = subprocess.run([sys.executable, "-c", FIFO_OFF], capture_output=True, text=True, timeout=60, env=env)
    lines = r.stdout.splitlines()
    assert lines[:2] == ["None True True", "True True"], r.stdout + r.stderr
    assert "SCHED_FIFO 6 not asked for (ORCCADD_SCHED_FIFO=off)" in lines[2], r.stdout
