"""`orccadctl replay RUN.mcap`: a logged run's measurements through the same tasks' modules,
offline, and the commands they give compared with the commands the run sent.

The tasks are built as the daemon built them: from the mission and task files the log carries
(`orccadd.mission`, or `--mission`), on the robot config (`--config`, else the one the run
record names), each task's parameters as the log started, the run's tunes applied at the ticks
that applied them, and `--set` on top. Each tick of a task's window (the rows whose `task` is
it) reads the recorded state back (`RecordedResource`), computes and commits as the control
loop does, switches as the loop switched (the outgoing command continued and blended), and the
command is compared with the recorded one: bit for bit by default (`tol`), since the law is
deterministic given its inputs and parameters.
"""

from __future__ import annotations

import hashlib
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from orccadd.config.robot import RobotConfig
from orccadd.daemon import deploy
from orccadd.daemon.mission import load_mission
from orccadd.errors import OrccaddError
from orccadd.model import RobotModel
from orccadd.modules.base import CommandMotion
from orccadd.offline.replayrun import RecordedRun, ReplayError, Tune
from orccadd.physres import PhysicalResource, backend_class
from orccadd.physres.description import ResourceDescription
from orccadd.robot import load_station_config
from orccadd.state import FloatArray, JointState
from orccadd.task import EventQueue, EventRegistry, RobotTask
from orccadd.task.motion import CommandHistory
from orccadd.types import CommandMode, Lifecycle, Phase, Status

# the status flags the resource itself sets (stops, limits): recomputed by the replay, not read
OWN_FLAGS = int(Status.STOPPING | Status.STOPPED | Status.TORQUE_OFF | Status.LIMIT_VIOLATION)


class RecordedResource(PhysicalResource):
    """A resource that reads a log's recorded state back, tick by tick, and keeps the commands
    instead of sending them. Its description, limits, workspace and checks are those of the
    config's own backend: `write` clamps and flags as the real resource did."""

    Settings = object

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        return backend_class(config.resource.backend, config.source).describe(config)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        self._row: FloatArray = np.zeros(3 * self.dof)
        self._status = 0

    def play(
        self, q: FloatArray, dq: FloatArray, tau: FloatArray, status: int, signals: dict[str, FloatArray]
    ) -> None:
        """What the next `read` measures (`signals`: the resource's own, by name)."""
        n = self.dof
        self._row[:n], self._row[n : 2 * n], self._row[2 * n :] = q, dq, tau
        self._status = status & ~OWN_FLAGS
        for name, value in signals.items():
            self.signals[name][:] = value

    def continue_position(self, command: FloatArray) -> None:
        """The position command the run had sent last (the next one's step is checked from it)."""
        self._last_pos_cmd[:] = command

    def _read_into(self, t_s: float, state: JointState) -> int:
        state.vector[:] = self._row
        return self._status

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        return 0

    def _begin_safe_stop(self) -> None:
        self._mark_stopped(torque_off=False)

    def _on_configure(self) -> None:
        pass

    def _on_activate(self, mode: CommandMode) -> None:
        pass

    def _on_deactivate(self) -> None:
        pass

    def _on_shutdown(self) -> None:
        pass


@dataclass(frozen=True)
class Divergence:
    """The first tick where the replay and the run differ: the signal, both values, by how much."""

    tick: int
    time_s: float  # since the task's window started
    signal: str  # `cmd.<joint>`, `wrote`, `phase`
    run: float
    replay: float

    @property
    def by(self) -> float:
        return abs(self.replay - self.run)


@dataclass
class TaskReplay:
    """One window of a task (its `occurrence`-th run in the log)."""

    task: str
    occurrence: int
    first_tick: int
    ticks: int
    max_diff: float = 0.0  # the largest command difference over the window
    differing_ticks: int = 0
    divergence: Divergence | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def key(self) -> str:
        return self.task if self.occurrence == 1 else f"{self.task}#{self.occurrence}"


@dataclass
class ReplayReport:
    path: Path
    mission: str
    config: str
    tolerance: float
    windows: list[TaskReplay]
    notes: list[str]
    elapsed_s: float = 0.0
    run_s: float = 0.0  # the replayed windows' length in the run

    @property
    def identical(self) -> bool:
        return all(w.divergence is None for w in self.windows)

    @property
    def first(self) -> TaskReplay | None:
        diverged = [w for w in self.windows if w.divergence is not None]
        return min(diverged, key=lambda w: w.divergence.tick if w.divergence else 0, default=None)


@dataclass
class _Built:
    resource: RecordedResource
    tasks: dict[str, RobotTask]
    queue: EventQueue
    registry: EventRegistry
    config: RobotConfig


def replay(
    run: RecordedRun,
    config: Path | None = None,
    mission: Path | None = None,
    task: str = "",
    sets: Sequence[tuple[str, Any]] = (),
    tolerance: float = 0.0,
) -> ReplayReport:
    """Replay `run` (every mission task's windows, or `task`'s); `ReplayError` for what it cannot."""
    notes: list[str] = []
    config_path = _config_path(run, config, notes)
    built = _build(run, config_path, mission, notes)
    if task and task not in built.tasks:
        known = ", ".join(built.tasks)
        raise ReplayError(f"{run.path}: the mission has no task {task!r} (its tasks: {known})")
    _start_parameters(run, built, notes)
    for path, value in sets:
        _set(built, path, value, "--set")
    windows = _windows(run, built, task)
    if not windows:
        what = f"task {task}" if task else "any of the mission's tasks"
        raise ReplayError(f"{run.path}: the log has no tick of {what}")
    player = _Player(run, built, tolerance, notes, sets)
    t0 = time.perf_counter()
    out = [player.window(name, occ, a, b) for name, occ, a, b in windows]
    report = ReplayReport(run.path, run.mission.get("name", ""), str(config_path), tolerance, out, notes)
    report.elapsed_s = time.perf_counter() - t0
    period = built.config.control_period_s
    report.run_s = sum(w.ticks for w in out) * period
    return report


def _config_path(run: RecordedRun, given: Path | None, notes: list[str]) -> Path:
    if given is not None:
        path = given
    else:
        named = run.meta.get("config", "")
        if not named:
            raise ReplayError(f"{run.path}: its run record names no robot config: give one with --config")
        path = Path(named)
        if not path.is_file():
            raise ReplayError(
                f"{run.path}: the run's robot config {named} is not on this machine: give it with --config"
            )
    want = run.meta.get("config_sha256", "")
    try:
        have = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as e:
        raise ReplayError(f"--config {path}: {e.strerror or e}") from None
    if want and have != want:
        notes.append(f"{path} is not the config the run had (sha256 {have[:12]} here, {want[:12]} then)")
    return path


def _build(run: RecordedRun, config_path: Path, mission: Path | None, notes: list[str]) -> _Built:
    try:
        cfgs = load_station_config(config_path).resources  # a robot config, or a station of one resource
        if len(cfgs) != 1:
            names = ", ".join(c.resource.name for c in cfgs)
            raise ReplayError(
                f"{config_path}: a station of {len(cfgs)} resources ({names}): replay takes one's run"
            )
        cfg = cfgs[0]
        res = RecordedResource(cfg, RobotModel.from_config(cfg))
    except OrccaddError as e:
        raise ReplayError(f"--config {config_path}: {e}") from None
    res.configure()
    queue, registry = EventQueue(1 << 16), EventRegistry()
    with tempfile.TemporaryDirectory(prefix="orccadd-replay-") as tmp:
        if mission is not None:
            path = mission
            notes.append(f"the mission and task files from {mission}, not the run's")
        else:
            files = {k.removeprefix("task:"): v for k, v in run.mission.items() if k.startswith("task:")}
            try:
                staged = deploy.stage(Path(tmp), "replay", run.mission["mission"], files)
            except OrccaddError as e:
                raise ReplayError(f"{run.path}: the mission it carries: {e}") from None
            path = staged.mission if isinstance(staged, deploy.Staged) else staged / "replay.mission"
        try:
            loaded = load_mission(path, {res.name: (res, queue)}, registry)
        except OrccaddError as e:
            raise ReplayError(f"the mission cannot be built for replay: {e}") from None
    return _Built(res, {t.name: t for t in loaded.tasks}, queue, registry, cfg)


def _start_parameters(run: RecordedRun, built: _Built, notes: list[str]) -> None:
    """Each task's parameters as they were when the log started (tuned before, or set)."""
    for name, params in run.parameters.items():
        t = built.tasks.get(name)
        if t is None:
            continue
        current = {p["name"]: p for p in t.parameters()}
        for path, value in params.items():
            p = current.get(path)
            if p is None or p["value"] == value:
                continue
            if not p["tunable"]:
                notes.append(f"{name}.{path} was {value} in the run, {p['value']} here (not tunable)")
                continue
            _set(built, f"{name}.{path}", value, "the run's start")


def _set(built: _Built, path: str, value: Any, what: str) -> None:
    task, _, param = path.partition(".")
    t = built.tasks.get(task)
    if t is None or not param:
        known = ", ".join(built.tasks)
        raise ReplayError(f"{what}: {path!r} is not TASK.MODULE.PARAM of the mission (tasks: {known})")
    try:
        t.tune(param, value)
    except OrccaddError as e:
        raise ReplayError(f"{what}: {e}") from None


def _windows(run: RecordedRun, built: _Built, only: str) -> list[tuple[str, int, int, int]]:
    """(task, occurrence, first row, end row) of each run of a mission task in the log."""
    out: list[tuple[str, int, int, int]] = []
    seen: dict[str, int] = {}
    ids, seq = run.scalars["task"], run.seq
    start = 0
    for r in range(1, run.rows + 1):
        if r < run.rows and ids[r] == ids[start] and seq[r] == seq[r - 1] + 1:
            continue
        name = run.task_at(start)
        if name in built.tasks:
            seen[name] = seen.get(name, 0) + 1
            if not only or name == only:
                out.append((name, seen[name], start, r))
        start = r
    return out


class _Player:
    """Plays windows in log order, the run's tunes applied as their ticks come."""

    def __init__(
        self,
        run: RecordedRun,
        built: _Built,
        tolerance: float,
        notes: list[str],
        sets: Sequence[tuple[str, Any]],
    ) -> None:
        self.run = run
        self.b = built
        self.tol = tolerance
        self.notes = notes
        self.tunes = sorted(run.tunes, key=lambda t: t.tick)
        self.next_tune = 0
        self.overridden = {p for p, _ in sets}
        self.period_s = built.config.control_period_s
        self.blend_ticks = int(round(built.config.daemon.switch_blend_s / self.period_s))
        # the resource's own signals the log has (a wrench, a camera's features); those it lacks
        # read as zeros, and a task that reads them diverges
        own = built.resource.signals
        self.signals = {k: v for k, v in run.signals.items() if k in own and v.shape[1] == own[k].size}
        missing = [k for k in own if k not in self.signals]
        if missing:
            notes.append(f"the log lacks the resource's {', '.join(missing)}: replayed as zeros")

    def _signals_at(self, row: int) -> dict[str, FloatArray]:
        return {name: values[row] for name, values in self.signals.items()}

    def _tunes_until(self, tick: int) -> None:
        while self.next_tune < len(self.tunes) and self.tunes[self.next_tune].tick <= tick:
            self._apply(self.tunes[self.next_tune])
            self.next_tune += 1

    def _apply(self, tune: Tune) -> None:
        t = self.b.tasks.get(tune.task)
        if t is None:
            return  # the Hold task's, or another resource's
        param = tune.path.split(".", 1)[1]
        if tune.path.partition("[")[0] in self.overridden:
            self.notes.append(f"the run's tune of {tune.path} at tick {tune.tick}: --set overrides it")
            return
        value: Any = tune.value[0] if len(tune.value) == 1 else tune.value
        if tune.cut:
            current = {p["name"]: p["value"] for p in t.parameters()}[param]
            value = [*tune.value, *current[len(tune.value) :]]
            self.notes.append(f"the tune of {tune.path} at tick {tune.tick} was logged cut: its first values")
        try:
            t.tune(param, value)
        except OrccaddError as e:
            self.notes.append(f"the run's tune of {tune.path} at tick {tune.tick} could not be applied: {e}")
            return
        self.notes.append(f"the run's tune {tune.path} = {value} applied at tick {tune.tick}, as in the run")

    def window(self, name: str, occurrence: int, a: int, b: int) -> TaskReplay:
        run, res, task = self.run, self.b.resource, self.b.tasks[name]
        seq, sc, vec = run.seq, run.scalars, run.vectors
        out = TaskReplay(name, occurrence, int(seq[a]), b - a)
        self._tunes_until(int(seq[a]))
        self._switch_to(task, a)
        joints = run.joints
        t_first = float(sc["t_s"][a])
        for r in range(a, b):
            self._tunes_until(int(seq[r]))
            res.play(vec["q"][r], vec["dq"][r], vec["tau"][r], int(sc["status"][r]), self._signals_at(r))
            t_s = float(sc["t_s"][r])
            task.compute(t_s)
            task.commit(t_s)
            div: Divergence | None = None
            ran_wrote = bool(sc["wrote"][r])
            if ran_wrote != task.wrote:
                div = Divergence(int(seq[r]), t_s - t_first, "wrote", float(ran_wrote), float(task.wrote))
            elif ran_wrote:
                d = np.abs(res.last_command - vec["cmd"][r])
                j = int(np.argmax(d))
                m = float(d[j])
                if not m <= self.tol:  # (NaN: diverged too)
                    out.differing_ticks += 1
                    out.max_diff = max(out.max_diff, m) if np.isfinite(m) else float("inf")
                    div = Divergence(
                        int(seq[r]),
                        t_s - t_first,
                        f"cmd.{joints[j]}",
                        float(vec["cmd"][r][j]),
                        float(res.last_command[j]),
                    )
            if div is not None and out.divergence is None:
                out.divergence = div
            if task.phase is Phase.FAULT:
                out.notes.append(f"the replayed law raised {task.fault_reason} at tick {int(seq[r])}")
                break
        self.b.queue.drain()
        task.deactivate()
        return out

    def _switch_to(self, task: RobotTask, a: int) -> None:
        """As the control loop switches: the mode, then the outgoing command continued (and its
        motion for a position command) unless the arm was stopped or the task is the first."""
        run, res = self.run, self.b.resource
        sc, vec = run.scalars, run.vectors
        mode = task.signature.command
        prev = a - 1
        contiguous = prev >= 0 and run.seq[prev] == run.seq[a] - 1
        # the state the switch sees: this tick's (the automaton switches within the tick that
        # raised the event, after the outgoing task has read the resource)
        res.play(vec["q"][a], vec["dq"][a], vec["tau"][a], int(sc["status"][a]), self._signals_at(a))
        res.read(float(sc["t_s"][a]))
        if res.lifecycle is not Lifecycle.ACTIVE:
            res.activate(mode)
        elif mode is not res.mode:
            res.perform_mode_switch(mode)
        if contiguous and int(sc["mode"][prev]) == CommandMode.POSITION:
            res.continue_position(vec["cmd"][prev])
        task.activate()
        stopped = contiguous and int(sc["status"][prev]) & int(Status.STOPPING | Status.STOPPED)
        if not contiguous or stopped or not sc["wrote"][prev] or int(sc["mode"][prev]) != mode:
            return
        motion: CommandMotion | None = None
        if mode is CommandMode.POSITION:
            prev_task = self.b.tasks.get(run.task_at(prev))
            hist = CommandHistory(res.dof, prev_task.period_s if prev_task else self.period_s)
            first = prev
            while first > max(prev - 2, 0) and sc["task"][first - 1] == sc["task"][prev]:
                first -= 1
            for r in range(first, prev + 1):
                hist.record(vec["cmd"][r])
            motion = CommandMotion(res.dof)
            hist.motion(motion)
        task.continue_from(vec["cmd"][prev].copy(), self.blend_ticks, motion)


def parse_sets(items: Sequence[str]) -> list[tuple[str, Any]]:
    """`TASK.MODULE.PARAM=VALUE` (a number or `[a, b, ...]`) → (path, value); `ReplayError` else."""
    import json

    out: list[tuple[str, Any]] = []
    for item in items:
        path, sep, text = item.partition("=")
        try:
            value = json.loads(text)
        except ValueError:
            value = None
        number = isinstance(value, int | float | list) and not isinstance(value, bool)
        if not sep or not path.strip() or not number:
            raise ReplayError(f"--set {item!r}: TASK.MODULE.PARAM=VALUE, the value a number or [a, b, ...]")
        out.append((path.strip(), value))
    return out


def report_dict(r: ReplayReport) -> dict[str, Any]:
    def div(d: Divergence | None) -> Mapping[str, Any] | None:
        if d is None:
            return None
        return {
            "tick": d.tick,
            "time_s": round(d.time_s, 6),
            "signal": d.signal,
            "run": d.run,
            "replay": d.replay,
            "by": d.by,
        }

    return {
        "run": str(r.path),
        "mission": r.mission,
        "config": r.config,
        "tolerance": r.tolerance,
        "identical": r.identical,
        "tasks": [
            {
                "task": w.key,
                "first_tick": w.first_tick,
                "ticks": w.ticks,
                "differing_ticks": w.differing_ticks,
                "max_diff": w.max_diff,
                "divergence": div(w.divergence),
                "notes": w.notes,
            }
            for w in r.windows
        ],
        "notes": r.notes,
        "elapsed_s": round(r.elapsed_s, 3),
        "run_s": round(r.run_s, 3),
    }
