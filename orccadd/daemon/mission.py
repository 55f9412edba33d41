"""Loading a mission into the daemon: compile, verify, and prepare every Robot-Task off the hot path.

Only a mission that passes every check is loaded; the automaton that was checked is the one that
runs. Each task of the mission is built once, here (modules instantiated, ports bound, parameters
set from the mission's `set` lines), so that switching at run time only flips a pointer.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from orccadd.automaton import Automaton, Network, NetworkRunner, Report, Runner
from orccadd.errors import OrccaddError, VerificationError
from orccadd.mission import Bindings, TaskFiles, build_mission_tasks, check_mission
from orccadd.task import EventRegistry, RobotTask
from orccadd.task.spec import TaskSpec


class MissionRunner(Protocol):
    """How the daemon steps a mission: `Runner` (one automaton) or `NetworkRunner` (a network,
    whose states are snapshots). A state is opaque to the daemon; `number` is what the trace
    records of it."""

    def snapshot(self) -> Any: ...
    def restore(self, state: Any) -> None: ...
    def peek(self, state: Any, inputs: int) -> tuple[Any, int]: ...
    def active_in(self, state: Any) -> tuple[int, ...]: ...
    def waits(self, state: Any) -> bool: ...
    def number(self, state: Any) -> int: ...


@dataclass(frozen=True)
class LoadedMission:
    """A verified mission with its tasks built for this robot's resources."""

    file: str
    automaton: Automaton | Network  # a network: a `par` of independent branches compiled apart
    report: Report
    tasks: tuple[RobotTask, ...]  # index i ↔ automaton.program.tasks[i]
    event_bits: dict[int, int]  # event registry id → the automaton's input bit
    deployment: str = ""  # the content hash of a deployed mission (orccadd/daemon/deploy.py)

    @property
    def name(self) -> str:
        return self.automaton.program.name

    @property
    def top(self) -> Automaton:
        """The automaton whose action bits every reaction uses (a network's context)."""
        return self.automaton.context if isinstance(self.automaton, Network) else self.automaton

    def new_runner(self) -> MissionRunner:
        """A runner for a new run, at the mission's initial state."""
        a = self.automaton
        return NetworkRunner(a) if isinstance(a, Network) else Runner(a)

    def describe(self) -> dict[str, object]:
        p = self.automaton.program
        procs = [pr.name for pr in p.ast.procedures if pr.role == "main"]
        cell = {n for n, _ in (*p.remote_inputs, *p.lost_inputs)}
        return {
            "name": p.name,
            "file": self.file,
            "deployment": self.deployment,
            "main_procedure": procs[0] if procs else "",
            "tasks": [t.name for t in p.tasks],
            "task_resources": [t.resource.name for t in self.tasks],  # the resource each runs on
            "tunables": [t.tunable_names for t in self.tasks],  # per task: what a tune record names
            "inputs": list(p.inputs),
            "operator_inputs": [
                n
                for n, k in zip(p.inputs, p.input_kind, strict=True)
                if k == "operator" and "." not in n and n not in cell
            ],
            "remote_inputs": [list(x) for x in p.remote_inputs],  # [input, peer]: `from "peer"`
            "lost_inputs": [list(x) for x in p.lost_inputs],  # [input, peer]: `lost "peer"`
            "cell_outputs": list(p.cell_outputs),  # emitted: published to the cell
            "resource_inputs": [
                n for n, k in zip(p.inputs, p.input_kind, strict=True) if k == "operator" and "." in n
            ],
            "resource_outputs": [n for n in p.internals if "." in n],
            "fault_inputs": [n for n, k in zip(p.inputs, p.input_kind, strict=True) if k == "fault"],
            "actions": list(self.top.action_names),
            "states": self.automaton.n_states,
            "transitions": self.automaton.n_transitions,
            "network": self.automaton.describe() if isinstance(self.automaton, Network) else None,
        }


def load_mission(path: str | Path, bindings: Bindings, registry: EventRegistry) -> LoadedMission:
    """Compile, verify, check against this robot, build the tasks. Raises `OrccaddError`
    (MissionError with file:line:col, or VerificationError with the counterexamples)."""
    automaton, report = compile_and_verify(path)
    return prepare_mission(path, automaton, report, bindings, registry)


def compile_and_verify(
    path: str | Path, text: str | None = None, task_files: TaskFiles | None = None
) -> tuple[Automaton | Network, Report]:
    """The long, pure part of a load (parse, compile, verify): the real-time process runs it in
    a child process (`orccadd.daemon.compile_worker`), so that it never holds the control
    thread's interpreter lock. `VerificationError` with the counterexamples if a check fails.
    The same checks as `orccadctl check` (`orccadd.mission.check_mission`). `text`: the
    mission already read; `task_files`: how its task files are read (and kept)."""
    automaton, report = check_mission(path, text=text, task_files=task_files)
    if not report.ok:
        raise VerificationError(f"{path}: the mission fails its checks:\n{report.format()}")
    return automaton, report


def prepare_mission(
    path: str | Path,
    automaton: Automaton | Network,
    report: Report,
    bindings: Bindings,
    registry: EventRegistry,
    specs: dict[str, TaskSpec] | None = None,
    data: Mapping[str, object] | None = None,
) -> LoadedMission:
    """Check a verified mission against this robot's resources and build its tasks
    (milliseconds). `bindings`: each resource by name with its control loop's event queue.
    `specs`: the task files as the compiler read them (path → spec), so the tasks built are the
    ones it checked and no file is read again here; None: read them. `data`: what modules take
    beyond their parameters, by `TASK.MODULE` (`build_mission_tasks`)."""
    if specs is None:
        tasks, bits = build_mission_tasks(automaton, bindings, registry, data=data)
    else:

        def spec(p: Path) -> TaskSpec:
            if str(p) not in specs:
                raise OrccaddError(f"{p}: not among the task files the compiler read")
            return specs[str(p)]

        tasks, bits = build_mission_tasks(automaton, bindings, registry, spec, data)
    return LoadedMission(str(path), automaton, report, tasks, bits)
