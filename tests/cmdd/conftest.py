"""A telemetry block written by a stand-in for the control loop (no real-time process): ticks
with known values, trace records, a command mode to switch; and the names the daemon's
`describe` would give them."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from orccadd.cmdd import views
from orccadd.wire.schema import TRACE_IDX, CommandMode, Layout, R, T, TickLayout, Trace
from orccadd.wire.telemetry import TelemetryBlock

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "configs/urdf/ur5e.urdf"
PERIOD_S = 0.002
T0_S = 1000.0  # the loop clock at tick 0 (not 0: the log's origin must be subtracted)
DESC: dict[str, Any] = {
    "robot": "test-arm",
    "generation": 0,
    "joints": ["shoulder_pan_joint", "elbow_joint"],
    "tasks": ["Hold", "Approach"],
    "events": ["Approach.T1.TrackingDrift", "Approach.T3.LimitViolation"],
    "event_kinds": ["t1", "t3"],
    "faults": [
        {
            "n": 1,
            "event": "Approach.T3.LimitViolation",
            "kind": "limit",
            "resource": "arm",
            "joint": "elbow_joint",
            "code": 0,
            "text": "measured position of elbow_joint 3.2 rad outside [-3.1, 3.1]",
        }
    ],
    "hold_tunables": ["pd.kd", "pd.kp"],
    "mission": {
        "name": "m",
        "inputs": ["start", "Approach.done"],
        "actions": ["Approach", "Stop"],
        "tasks": ["Approach"],
        "tunables": [["ct.kd", "ct.kp", "traj.target_rad"]],
    },
}


class FakeLoop:
    """Writes tick and trace records as the real-time process does."""

    def __init__(self, tel: TelemetryBlock, period_s: float = PERIOD_S) -> None:
        self.tel = tel
        self.period_s = period_s
        self.mode = CommandMode.TORQUE

    @property
    def seq(self) -> int:
        return int(self.tel.header[4])  # H.TICK_HEAD: ticks written so far

    def t_s(self, seq: int) -> float:
        return T0_S + seq * self.period_s

    def ticks(self, n: int) -> None:
        n_j = self.tel.dof
        for _ in range(n):
            seq = self.seq + 1
            rec = self.tel.begin_tick()
            rec[T.T_S] = self.t_s(seq)
            rec[T.WAKE_US] = 20.0 + seq % 7
            rec[T.COMPUTE_US] = 90.0
            rec[T.TASK] = 1
            rec[T.PHASE] = 2
            rec[T.WROTE] = 1
            rec[T.MODE] = self.mode
            at = TickLayout(n_j)
            for j in range(n_j):
                rec[at.column("q", j)] = math.sin(seq * self.period_s + j)
                rec[at.column("dq", j)] = 0.1 * j
                rec[at.column("tau", j)] = 5.0 + j
                rec[at.column("cmd", j)] = 6.0 + j
            self.tel.commit_tick(rec, 0)

    def trace(
        self, kind: Trace, code: int = 0, inputs: Sequence[float] = (), actions: Sequence[float] = ()
    ) -> None:
        """A trace record at the time of the last tick."""
        rec = self.tel.begin_trace()
        rec[R.KIND] = kind
        rec[R.T_S] = self.t_s(self.seq)
        rec[R.WALL_S] = 1.7e9
        rec[R.STATE_FROM], rec[R.STATE_TO] = 0, 1
        rec[R.CODE] = code
        rec[R.N_IN], rec[R.N_ACT] = len(inputs), len(actions)
        base = len(R)
        rec[base : base + len(inputs)] = inputs
        rec[base + TRACE_IDX : base + TRACE_IDX + len(actions)] = actions
        self.tel.commit_trace(rec)


@pytest.fixture
def tel() -> Iterator[TelemetryBlock]:
    block = TelemetryBlock.create(Layout(dof=2, tick_len=4096, trace_len=64), PERIOD_S)
    try:
        yield block
    finally:
        block.close()


@pytest.fixture
def loop(tel: TelemetryBlock) -> FakeLoop:
    return FakeLoop(tel)


def decode(rec: np.ndarray) -> dict[str, Any]:
    return views.decode_trace(rec, DESC)
