"""Real-time setup: the PM QoS request that keeps CPUs out of deep idle is held, then released."""

from __future__ import annotations

import os
import struct

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
