"""What every fault test of a running orccadd checks at its end, from the telemetry ring (the last
16 s of ticks, every tick): the safe stop began within 2 control periods of the tick that showed
the fault, and no command outside the configured limits went to the device, in any tick."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from orccadd.config.robot import RobotConfig, read_robot_config
from orccadd.types import CommandMode, Status
from orccadd.wire.schema import TICK_FIELDS, H, T
from orccadd.wire.telemetry import TelemetryBlock

FloatArray = np.ndarray
SAFE = int(Status.STOPPING | Status.STOPPED)
STOP_WITHIN_TICKS = 2
NF = len(TICK_FIELDS)


def tick_records(telemetry: str) -> FloatArray:
    """Every tick record the ring still holds, oldest first."""
    tel = TelemetryBlock.attach(telemetry)
    try:
        head, ring = int(tel.header[H.TICK_HEAD]), tel.ticks.copy()
    finally:
        tel.close()
    n = len(ring)
    seqs = np.arange(max(1, head - n + 1), head + 1)
    recs = ring[(seqs - 1) % n]
    out: FloatArray = recs[recs[:, T.SEQ] == seqs]
    return out


def assert_commands_within_limits(recs: FloatArray, config: Path | RobotConfig) -> None:
    """Each command sent (the `cmd` vector of a tick that wrote one) inside the config's limits:
    positions in range and no faster than max velocity from the previous one, velocities and
    torques within their maxima."""
    cfg = config if isinstance(config, RobotConfig) else read_robot_config(config)
    j = cfg.joints
    dof = len(j)
    lo = np.array([x.position_min_rad for x in j])
    hi = np.array([x.position_max_rad for x in j])
    v = np.array([x.max_velocity_rad_s for x in j])
    tau = np.array([x.max_torque_nm for x in j])
    cmd = recs[:, NF + 3 * dof : NF + 4 * dof]
    mode = recs[:, T.MODE].astype(int)
    wrote = recs[:, T.WROTE] > 0
    eps = 1e-9
    pos = wrote & (mode == CommandMode.POSITION)
    bad = pos & np.any((cmd < lo - eps) | (cmd > hi + eps), axis=1)
    bad |= wrote & (mode == CommandMode.VELOCITY) & np.any(np.abs(cmd) > v + eps, axis=1)
    bad |= wrote & (mode == CommandMode.TORQUE) & np.any(np.abs(cmd) > tau + eps, axis=1)
    step_ok = np.all(np.abs(np.diff(cmd, axis=0)) <= v * cfg.control_period_s + eps, axis=1)
    moving = (recs[:, T.STATUS].astype(int) & SAFE) == 0  # a stop or a reset restarts from q
    consecutive = pos[1:] & pos[:-1] & moving[1:] & moving[:-1] & (np.diff(recs[:, T.SEQ]) == 1)
    bad[1:] |= consecutive & ~step_ok
    assert not bad.any(), f"commands outside the limits at ticks {recs[bad, T.SEQ][:10].astype(int).tolist()}"
    assert wrote.any(), "no command was sent at all: nothing was checked"


def ticks_to_safe_stop(recs: FloatArray, fault: Callable[[FloatArray], bool]) -> int:
    """Ticks from the first record where `fault` holds to the first showing the safe stop."""
    seq = recs[:, T.SEQ].astype(int)
    first = next((i for i, r in enumerate(recs) if fault(r)), None)
    assert first is not None, "no tick shows the fault"
    stop = next((i for i in range(first, len(recs)) if int(recs[i, T.STATUS]) & SAFE), None)
    assert stop is not None, "no tick shows the safe stop after the fault"
    return int(seq[stop] - seq[first])


def assert_safe_stop_in_time(recs: FloatArray, fault: Callable[[FloatArray], bool]) -> None:
    n = ticks_to_safe_stop(recs, fault)
    assert n <= STOP_WITHIN_TICKS, f"safe stop {n} ticks after the fault (at most {STOP_WITHIN_TICKS})"
