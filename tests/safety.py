"""What every fault test checks at its end (docs/fault-matrix.md): the safe stop began within 2
control ticks of the first tick that showed the fault, and no tick sent a command outside the
config's limits. The ticks come from a running orccadd's telemetry ring (`from_telemetry`, the
last 16 s, every tick) or from a control loop run by the test (`TickRecorder`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orccadd.config.robot import RobotConfig, read_robot_config
from orccadd.task.loop import ControlLoop
from orccadd.types import CommandMode, Status
from orccadd.wire.schema import H, T, TickLayout
from orccadd.wire.telemetry import TelemetryBlock

FloatArray = np.ndarray
SAFE = int(Status.STOPPING | Status.STOPPED)
STOP_WITHIN_TICKS = 2


@dataclass
class Ticks:
    """One row per tick, in order."""

    seq: FloatArray
    t_s: FloatArray
    status: FloatArray  # Status flags
    mode: FloatArray  # CommandMode of `cmd`
    wrote: FloatArray  # 1 if the tick sent a command
    cmd: FloatArray  # (ticks, dof): the command sent to the device
    compute_us: FloatArray


def from_telemetry(telemetry: str) -> Ticks:
    """Every tick record the ring of a running orccadd still holds, oldest first."""
    tel = TelemetryBlock.attach(telemetry)
    try:
        head, ring, dof = int(tel.header[H.TICK_HEAD]), tel.ticks.copy(), int(tel.header[H.DOF])
    finally:
        tel.close()
    n = len(ring)
    seqs = np.arange(max(1, head - n + 1), head + 1)
    recs = ring[(seqs - 1) % n]
    recs = recs[recs[:, T.SEQ] == seqs]
    return Ticks(
        recs[:, T.SEQ], recs[:, T.T_S], recs[:, T.STATUS], recs[:, T.MODE], recs[:, T.WROTE],
        recs[:, TickLayout(dof).cmd], recs[:, T.COMPUTE_US],
    )  # fmt: skip


class TickRecorder(ControlLoop):
    """A control loop that keeps, for every tick, what the telemetry of the daemon would."""

    rows: list[list[float]]

    def after_step(self, t_s: float) -> None:
        super().after_step(t_s)
        if not hasattr(self, "rows"):
            self.rows = []
        res, task = self.resource, self.active
        self.rows.append([
            float(self.stats.ticks), t_s, float(res.state.status), float(res.mode),
            float(task.wrote if task is not None else 0), self.stats.last_compute_ns * 1e-3,
            *res.last_command.tolist(),
        ])  # fmt: skip

    def ticks(self) -> Ticks:
        a = np.array(self.rows)
        return Ticks(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], a[:, 6:], a[:, 5])


def assert_commands_within_limits(ticks: Ticks, config: Path | RobotConfig) -> None:
    """Each command sent inside the config's limits: positions in range and no faster than max
    velocity from the previous one, velocities and torques within their maxima."""
    cfg = config if isinstance(config, RobotConfig) else read_robot_config(config)
    j = cfg.joints
    lo = np.array([x.position_min_rad for x in j])
    hi = np.array([x.position_max_rad for x in j])
    v = np.array([x.max_velocity_rad_s for x in j])
    tau = np.array([x.max_torque_nm for x in j])
    cmd, mode, wrote = ticks.cmd, ticks.mode.astype(int), ticks.wrote > 0
    eps = 1e-9
    pos = wrote & (mode == CommandMode.POSITION)
    bad = pos & np.any((cmd < lo - eps) | (cmd > hi + eps), axis=1)
    bad |= wrote & (mode == CommandMode.VELOCITY) & np.any(np.abs(cmd) > v + eps, axis=1)
    bad |= wrote & (mode == CommandMode.TORQUE) & np.any(np.abs(cmd) > tau + eps, axis=1)
    step_ok = np.all(np.abs(np.diff(cmd, axis=0)) <= v * cfg.control_period_s + eps, axis=1)
    moving = (ticks.status.astype(int) & SAFE) == 0  # a stop or a reset restarts from q
    consecutive = pos[1:] & pos[:-1] & moving[1:] & moving[:-1] & (np.diff(ticks.seq) == 1)
    bad[1:] |= consecutive & ~step_ok
    assert not bad.any(), f"commands outside the limits at ticks {ticks.seq[bad][:10].astype(int).tolist()}"
    assert wrote.any(), "no command was sent at all: nothing was checked"


def ticks_to_safe_stop(ticks: Ticks, fault: Callable[[int], bool]) -> int:
    """Ticks from the first tick `i` where `fault(i)` holds to the first showing the safe stop."""
    first = next((i for i in range(len(ticks.seq)) if fault(i)), None)
    assert first is not None, "no tick shows the fault"
    safe = (ticks.status.astype(int) & SAFE) != 0
    stop = next((i for i in range(first, len(safe)) if safe[i]), None)
    assert stop is not None, "no tick shows the safe stop after the fault"
    return int(ticks.seq[stop] - ticks.seq[first])


def status_shows(ticks: Ticks, flags: Status) -> Callable[[int], bool]:
    return lambda i: bool(int(ticks.status[i]) & flags)


def assert_safe_stop_in_time(ticks: Ticks, fault: Callable[[int], bool]) -> None:
    n = ticks_to_safe_stop(ticks, fault)
    assert n <= STOP_WITHIN_TICKS, f"safe stop {n} ticks after the fault (at most {STOP_WITHIN_TICKS})"
