"""A logged run as `orccadctl compare` sees it: its MCAP read back (`logread.read_mcap`), the
automaton's instants from `/events` (inputs, actions, states, in order), each task's windows
(from the instant that starts it to the one that stops it), the command mode over time (the
`mode` events) and the signal columns by joint.

Every refusal is a `RunError` naming the file and what is wrong with it: not an MCAP, a
truncated or corrupted one, one without the channels a comparison needs, two runs of different
missions.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from orccadd.errors import OrccaddError
from orccadd.offline.logread import CsvLogData, is_mcap, read_mcap

ARG_ACTIONS = ("start", "stop", "emit")  # the actions that take a name (`start Reach`)
_INSTANT = re.compile(r"^(?P<inputs>.*?) -> (?P<actions>.*) \(state (?P<src>\S+) -> (?P<dst>\S+)\)$")
MISSION_KEYS = ("mission", "mission_name")  # where a log's metadata may name its mission


class RunError(OrccaddError):
    """A log that cannot be compared: the message names the file and what is wrong."""


@dataclass(frozen=True)
class Instant:
    """One reaction of the automaton as logged: `n` counts from 1 in its run."""

    n: int
    time_s: float
    inputs: str  # `Home.done`, `A+B`, `(no input)`
    actions: tuple[str, ...]  # `stop Home`, `start Reach`, `success`
    src: str
    dst: str

    def words(self) -> str:
        acts = " ".join(self.actions) or "(no action)"
        return f"{self.inputs} -> {acts} (state {self.src} -> {self.dst}) at {self.time_s:.3f} s"

    def same_reaction(self, other: Instant) -> bool:
        """The same inputs and the same actions (the states are shown, not compared: they
        are the same in two runs of one compiled mission)."""
        return self.inputs == other.inputs and self.actions == other.actions


@dataclass(frozen=True)
class TaskWindow:
    """One run of a task: from the instant that started it to the one that stopped it (`None`:
    still running when the log ended, or ended by a safe stop without a `stop` action)."""

    task: str
    occurrence: int  # 1 for its first run in the log, 2 for the second...
    start_s: float
    stop_s: float | None

    @property
    def key(self) -> str:
        return self.task if self.occurrence == 1 else f"{self.task}#{self.occurrence}"

    def end_s(self, log_end_s: float) -> float:
        return self.stop_s if self.stop_s is not None else log_end_s


@dataclass
class Run:
    """A run's log, its instants and task windows, the command mode's changes."""

    path: Path
    log: CsvLogData
    instants: list[Instant]
    windows: list[TaskWindow]
    modes: list[tuple[float, str]] = field(default_factory=list)  # (time_s, mode name)

    @property
    def t(self) -> np.ndarray:
        return self.log.data[:, 0]

    @property
    def end_s(self) -> float:
        return float(self.t[-1])

    @property
    def mission(self) -> str | None:
        """The mission's name where the log's metadata carries it."""
        return next((self.log.meta[k] for k in MISSION_KEYS if self.log.meta.get(k)), None)

    @property
    def tasks(self) -> list[str]:
        return list(dict.fromkeys(w.task for w in self.windows))

    def joint_cols(self, signal: str) -> dict[str, int]:
        """The columns of a per-joint signal group (`q`): joint label → column. A station's joints
        are labelled by their resource (`left/elbow_joint`)."""
        out: dict[str, int] = {}
        for i, name in enumerate(self.log.columns[1:], start=1):
            base, dot, joint = name.partition(".")
            res, _, sig = base.rpartition("/")
            if dot and sig == signal:
                out[f"{res}/{joint}" if res else joint] = i
        return out

    def scalar_cols(self, signal: str) -> dict[str, int]:
        """The columns of a scalar signal (`wake_us`): resource ("" for one) → column."""
        out: dict[str, int] = {}
        for i, name in enumerate(self.log.columns[1:], start=1):
            res, _, sig = name.rpartition("/")
            if sig == signal:
                out[res] = i
        return out

    def mode_at(self, t: np.ndarray) -> np.ndarray:
        """The command mode's name at each time (`?` before the first `mode` event)."""
        if not self.modes:
            return np.full(t.shape, "?", dtype=object)
        times = np.array([m[0] for m in self.modes])
        names = np.array(["?", *(m[1] for m in self.modes)], dtype=object)
        return names[np.searchsorted(times, t, side="right")]

    def rows(self, w: TaskWindow) -> np.ndarray:
        """The indices of the rows of a task's ticks: from its start to its stop, that tick
        excluded (a law switch takes effect in the tick of its event: that tick is the next
        task's); to the log's end where it did not stop."""
        t = self.t
        inside = t < w.stop_s if w.stop_s is not None else t <= t[-1]
        return np.flatnonzero((t >= w.start_s) & inside)


def load_run(path: Path) -> Run:
    """A run from its MCAP; `RunError` naming the file for anything that is not a comparable log."""
    try:
        mcap = is_mcap(path)
    except OSError as e:
        raise RunError(f"{path}: cannot be read ({e.strerror or e})") from None
    if not mcap:
        hint = f" (a CSV log? compare reads the MCAP beside it, {path.with_suffix('.mcap').name})"
        raise RunError(f"{path}: not an MCAP file{hint if path.suffix == '.csv' else ''}")
    try:
        log = read_mcap(path)
    except ValueError as e:
        raise RunError(str(e)) from None
    if "orccadd.log" not in log.metadata:
        raise RunError(f"{path}: an MCAP file without orccadd's `orccadd.log` metadata: not an orccadd log")
    if not any(kind == "instant" for _, kind, _ in log.events):
        topics = "no /events channel" if not log.events else "no automaton instant on /events"
        raise RunError(
            f"{path}: {topics}: the reactive trace a comparison aligns is missing "
            "(start the log before the mission: `log start`, then `start`)"
        )
    instants = _instants(path, log)
    modes = [(t, name) for t, kind, name in log.events if kind == "mode"]
    return Run(path, log, instants, _windows(instants), modes)


def _instants(path: Path, log: CsvLogData) -> list[Instant]:
    out: list[Instant] = []
    for (t, kind, _), text in zip(log.events, log.details, strict=True):
        if kind != "instant":
            continue
        m = _INSTANT.match(text)
        if m is None:
            raise RunError(f"{path}: an instant on /events not as orccadd writes them: {text[:120]!r}")
        acts = m["actions"].strip()
        words = [] if acts == "(no action)" else acts.split()
        actions: list[str] = []
        for w in words:
            if actions and actions[-1] in ARG_ACTIONS:
                actions[-1] = f"{actions[-1]} {w}"
            else:
                actions.append(w)
        out.append(Instant(len(out) + 1, t, m["inputs"], tuple(actions), m["src"], m["dst"]))
    return out


def _windows(instants: list[Instant]) -> list[TaskWindow]:
    """Each task's runs: from `start T` to the next `stop T` (or the log's end)."""
    open_at: dict[str, float] = {}
    count: dict[str, int] = {}
    out: list[TaskWindow] = []
    for i in instants:
        for a in i.actions:
            verb, _, task = a.partition(" ")
            if verb == "stop" and task in open_at:
                count[task] = count.get(task, 0) + 1
                out.append(TaskWindow(task, count[task], open_at.pop(task), i.time_s))
            elif verb == "start":
                open_at[task] = i.time_s
    for task, start in open_at.items():
        count[task] = count.get(task, 0) + 1
        out.append(TaskWindow(task, count[task], start, None))
    return sorted(out, key=lambda w: w.start_s)


def same_mission(a: Run, b: Run) -> tuple[str, str]:
    """How the two runs are known to be of one mission (`RunError` if they are not): by the
    mission's name where both logs carry it, else by their tasks' names (one run's tasks among
    the other's: a run cut short by a fault ran fewer)."""
    if a.mission is not None and b.mission is not None:
        if a.mission != b.mission:
            raise RunError(
                f"{b.path}: a run of mission {b.mission}, {a.path} of {a.mission} "
                "(the missions' names in the logs' metadata): compare compares two runs of one mission"
            )
        return "metadata", f"mission {a.mission} (the logs' metadata)"
    ta, tb = set(a.tasks), set(b.tasks)
    if not (ta <= tb or tb <= ta):
        raise RunError(
            f"{b.path}: ran tasks {', '.join(b.tasks)}; {a.path} ran {', '.join(a.tasks)}: two different "
            "missions (the logs do not name their mission: told by the tasks' names, neither run's "
            "among the other's)"
        )
    return (
        "task names",
        f"tasks {', '.join(a.tasks if len(ta) >= len(tb) else b.tasks)} (by the tasks' names)",
    )
