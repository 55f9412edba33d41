"""The automaton thread's writes to the telemetry block: trace records and the status area.

(The control thread writes its tick records itself, in `SwitchingLoop`.) Nothing here waits.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from orccadd.wire.schema import TRACE_IDX, R, S, Trace
from orccadd.wire.telemetry import TelemetryBlock


class Publisher:
    def __init__(self, tel: TelemetryBlock) -> None:
        self.tel = tel
        self.mission_gen = 0  # stamped on every trace record: the mission whose names it uses

    def trace(
        self,
        kind: Trace,
        t_s: float,
        code: int = 0,
        s_from: int = -1,
        s_to: int = -1,
        inputs: Sequence[float] | None = None,
        actions: Sequence[float] | None = None,
    ) -> None:
        """One trace record: an automaton instant, a task event or an operator action."""
        rec = self.tel.begin_trace()
        rec[R.KIND] = kind
        rec[R.T_S] = t_s
        rec[R.WALL_S] = time.time()
        rec[R.STATE_FROM] = s_from
        rec[R.STATE_TO] = s_to
        rec[R.CODE] = code
        ins = list(inputs or [])[:TRACE_IDX]
        acts = list(actions or [])[:TRACE_IDX]
        rec[R.N_IN] = len(ins)
        rec[R.N_ACT] = len(acts)
        rec[R.MISSION_GEN] = self.mission_gen
        base = len(R)
        rec[base : base + len(ins)] = ins
        rec[base + TRACE_IDX : base + TRACE_IDX + len(acts)] = acts
        self.tel.commit_trace(rec)

    def status(self, values: dict[S, float]) -> None:
        self.tel.write_status({int(k): v for k, v in values.items()})
