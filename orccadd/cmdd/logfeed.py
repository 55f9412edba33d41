"""What a log writes, read once from the telemetry block for every file of the log (CSV, MCAP):
the tick records after a point, the reactive trace decoded (automaton instants, task events,
operator commands) and the changes of command mode (which give the `cmd` signals their unit).

Times are seconds since the log's origin: the loop-clock time of the last tick before the log
started, so the first row is about one period. A log carried on by another command daemon keeps
its origin (it is in the state file and in the CSV's header).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from orccadd.cmdd import views
from orccadd.fault import StopCause
from orccadd.wire.foxglove_schemas import CMD_UNIT
from orccadd.wire.schema import CommandMode, H, R, T, exception_of, tune_words
from orccadd.wire.telemetry import RingReader, TelemetryBlock

FloatArray = npt.NDArray[np.float64]

MODE_UNITS = {CommandMode.POSITION: "rad", CommandMode.VELOCITY: "rad/s", CommandMode.TORQUE: "N.m"}
UNITS = {
    "time_s": "s",
    "t_s": "s",
    "q": "rad",
    "dq": "rad/s",
    "tau": "N.m",
    "cmd": CMD_UNIT,
    "wake_us": "us",
    "compute_us": "us",
}  # the others (task, phase, wrote, status, mode) are ids, flags or 0/1: unit "1"


def unit(signal: str) -> str:
    """The unit of a signal or signal group (`q`, `q.elbow_joint`, a station's `left/q`, ...)."""
    return UNITS.get(base_signal(signal), "1")


def base_signal(label: str) -> str:
    """The tick field of a label or group: `q` of `q.elbow_joint` and of a station's `left/q.0`."""
    return label.partition(".")[0].rpartition("/")[2]


def mode_name(code: float) -> str:
    c = int(code)
    return CommandMode(c).name.lower() if c in CommandMode._value2member_map_ else f"#{c}"


@dataclass(frozen=True)
class LogOrigin:
    """Where a log's time starts: `time_s` = loop time − `t_s`."""

    start_utc: str  # the wall clock when the log started, ISO 8601 UTC
    wall_ns: int  # the same, in ns since the epoch (MCAP log times)
    t_s: float  # loop-clock time of the tick before the log's first row (0.0 before any tick)
    tick: int  # that tick's sequence number (0 before any tick)

    @staticmethod
    def now(tel: TelemetryBlock) -> LogOrigin:
        wall_ns = time.time_ns()
        rec = views.latest_tick(tel)
        t_s, tick = (float(rec[T.T_S]), int(rec[T.SEQ])) if rec is not None else (0.0, 0)
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(wall_ns // 10**9))
        return LogOrigin(f"{stamp}.{wall_ns % 10**9 // 1000:06d}Z", wall_ns, t_s, tick)

    @staticmethod
    def from_state(d: dict[str, Any]) -> LogOrigin:
        return LogOrigin(str(d["start_utc"]), int(d["wall_ns"]), float(d["t_s"]), int(d["tick"]))

    def to_state(self) -> dict[str, Any]:
        return asdict(self)

    def wall_ns_at(self, time_s: float) -> int:
        """The wall-clock time (ns since the epoch) of a log time."""
        return self.wall_ns + round(time_s * 1e9)


@dataclass(frozen=True)
class LogEvent:
    """One mark of a log: an instant, a task event, an operator command or a change of mode."""

    time_s: float
    seq: int  # the trace record's number (-1: a change of mode, seen in the tick records)
    kind: str  # instant, event, command, fault, mode, gap
    name: str  # what a plot writes: the instant's inputs, the event, the command, the mode
    detail: str = ""
    exception: int = 0  # 3: a type 3 exception or a safe stop's cause, 2: a type 2, 0: neither
    fault: dict[str, Any] | None = None  # a `fault` mark's cause (`orccadd.fault.StopCause`)


Decoder = Callable[[FloatArray], dict[str, Any]]  # a trace record → its names (`views.decode_trace`)


def decode_event(rec: FloatArray, decode: Decoder, origin: LogOrigin) -> LogEvent:
    d = decode(rec)
    t = float(rec[R.T_S]) - origin.t_s
    if d["kind"] == "instant":
        detail = f"-> {' '.join(d['actions']) or '(no action)'} (state {d['from']} -> {d['to']})"
        ex = exception_of(d)
        return LogEvent(t, d["seq"], "instant", "+".join(d["inputs"]) or "(no input)", detail, ex)
    if d["kind"] == "event":
        return LogEvent(t, d["seq"], "event", str(d["event"]), "(task event)", exception_of(d))
    if d["kind"] == "fault":
        cause = d["fault"]
        if "kind" not in cause:  # no longer kept by the daemon
            return LogEvent(t, d["seq"], "fault", f"#{cause['n']}", "(safe stop; cause no longer kept)", 3)
        c = StopCause.from_wire(cause)
        return LogEvent(t, d["seq"], "fault", c.event or c.fault.kind.value, str(c.fault), 3, cause)
    tune = d.get("tune")
    if tune:  # which parameter, before → after, the tick that applied it
        return LogEvent(t, d["seq"], "command", "tune", f"(operator) {tune_words(tune)}")
    return LogEvent(t, d["seq"], "command", str(d["command"]), "(operator)")


class LogFeed:
    """New tick records of a resource's block `tel` (those after tick `after_tick`) and, with
    the daemon's block `trace`, log events (trace records after `after_trace`), polled together."""

    def __init__(
        self,
        tel: TelemetryBlock,
        origin: LogOrigin,
        decode: Decoder,
        after_tick: int,
        trace: TelemetryBlock | None = None,
        after_trace: int | None = None,
    ) -> None:
        self.tel = tel
        self.origin = origin
        self.decode = decode
        self.ticks = RingReader(tel.ticks, tel.header, H.TICK_HEAD, from_now=True)
        self.trace: RingReader | None = None
        if trace is not None:
            self.trace = RingReader(trace.trace, trace.header, H.TRACE_HEAD, from_now=after_trace is None)
        oldest = max(0, int(tel.header[H.TICK_HEAD]) - len(tel.ticks))
        # a gap longer than the ring keeps (no command daemon for longer): its ticks are lost,
        # counted in `lost` and marked by a `gap` event where the rows resume
        self.gap_ticks = max(0, oldest - after_tick)
        self._gap_mark = self.gap_ticks > 0
        self.ticks.next = max(after_tick, oldest)
        if after_trace is not None and self.trace is not None:
            self.trace.next = max(after_trace, self.trace.next)
        self.last_mode: float | None = None

    @property
    def lost(self) -> int:
        """Ticks that will never be in the log: a gap beyond the ring, and any the ring
        overwrote before they were read."""
        return self.ticks.lost + self.gap_ticks

    @property
    def gap_lost(self) -> bool:
        return self.gap_ticks > 0

    def poll(self) -> tuple[FloatArray, list[LogEvent]]:
        """The new tick records and the new events (trace and mode changes), in time order."""
        recs = self.ticks.poll()
        trace = self.trace.poll() if self.trace is not None else np.empty((0, 0))
        events = [decode_event(r, self.decode, self.origin) for r in trace] if len(trace) else []
        events += self._mode_changes(recs)
        if self._gap_mark and len(recs):
            self._gap_mark = False
            seconds = self.gap_ticks * self.tel.period_s
            name = f"{self.gap_ticks} ticks lost ({seconds:.3f} s)"
            at = float(recs[0, T.T_S]) - self.origin.t_s
            events.append(
                LogEvent(at, -1, "gap", name, "(no command daemon ran for longer than the ring keeps)")
            )
        events.sort(key=lambda e: e.time_s)
        return recs, events

    def _mode_changes(self, recs: FloatArray) -> list[LogEvent]:
        if not len(recs):
            return []
        modes = recs[:, T.MODE]
        prev = np.concatenate([[modes[0] + 1 if self.last_mode is None else self.last_mode], modes[:-1]])
        self.last_mode = float(modes[-1])
        return [
            LogEvent(
                float(recs[i, T.T_S]) - self.origin.t_s, -1, "mode", mode_name(modes[i]), "(command mode)"
            )
            for i in np.flatnonzero(modes != prev)
        ]
