"""Loading a mission into the daemon: compile, verify, and prepare every Robot-Task off the hot path.

Only a mission that passes every check is loaded; the automaton that was checked is the one that
runs. Each task of the mission is built once, here (modules instantiated, ports bound, parameters
set from the mission's `set` lines), so that switching at run time only flips a pointer.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from orccadd.automaton import Automaton, Report
from orccadd.automaton import ast as A
from orccadd.errors import MissionError, OrccaddError, ParameterError, VerificationError
from orccadd.mission import check_mission
from orccadd.physres.base import PhysicalResource
from orccadd.task import EventQueue, EventRegistry, RobotTask, build_task, load_task_file


@dataclass(frozen=True)
class LoadedMission:
    """A verified mission with its tasks built for this robot's resource."""

    file: str
    automaton: Automaton
    report: Report
    tasks: tuple[RobotTask, ...]  # index i ↔ automaton.program.tasks[i]
    event_bits: dict[int, int]  # event registry id → the automaton's input bit

    @property
    def name(self) -> str:
        return self.automaton.program.name

    def describe(self) -> dict[str, object]:
        p = self.automaton.program
        procs = [pr.name for pr in p.ast.procedures if pr.role == "main"]
        return {
            "name": p.name,
            "file": self.file,
            "main_procedure": procs[0] if procs else "",
            "tasks": [t.name for t in p.tasks],
            "inputs": list(p.inputs),
            "operator_inputs": [n for n, k in zip(p.inputs, p.input_kind, strict=True) if k == "operator"],
            "actions": list(self.automaton.action_names),
            "states": self.automaton.n_states,
            "transitions": self.automaton.n_transitions,
        }


def _err(decl_loc: A.Loc, text: str, msg: str) -> MissionError:
    return MissionError(decl_loc.file, decl_loc.line, decl_loc.col, msg, text)


def load_mission(
    path: str | Path, resource: PhysicalResource, registry: EventRegistry, queue: EventQueue
) -> LoadedMission:
    """Compile, verify, check against this robot, build the tasks. Raises `OrccaddError`
    (MissionError with file:line:col, or VerificationError with the counterexamples)."""
    automaton, report = compile_and_verify(path)
    return prepare_mission(path, automaton, report, resource, registry, queue)


def compile_and_verify(path: str | Path) -> tuple[Automaton, Report]:
    """The long, pure part of a load (parse, compile, verify): the real-time process runs it in
    a child process (`orccadd.daemon.compile_worker`), so that it never holds the control
    thread's interpreter lock. `VerificationError` with the counterexamples if a check fails.
    The same checks as `orccadctl check` (`orccadd.mission.check_mission`)."""
    automaton, report = check_mission(path)
    if not report.ok:
        raise VerificationError(f"{path}: the mission fails its checks:\n{report.format()}")
    return automaton, report


def prepare_mission(
    path: str | Path,
    automaton: Automaton,
    report: Report,
    resource: PhysicalResource,
    registry: EventRegistry,
    queue: EventQueue,
) -> LoadedMission:
    """Check a verified mission against this robot and build its tasks (milliseconds)."""
    p = automaton.program
    text = p.text
    for decl in p.ast.tasks:
        if decl.resource != resource.name:
            raise _err(
                decl.loc,
                text,
                f"task {decl.name} runs on `{decl.resource}`, but this robot's resource is `{resource.name}`",
            )
    tasks = [_build(decl, p.file, text, resource, registry, queue) for decl in p.ast.tasks]
    bits: dict[int, int] = {}
    for i, name in enumerate(p.inputs):
        if p.input_task[i] < 0:
            continue
        try:
            bits[registry.id(name)] = 1 << i
        except KeyError:
            raise OrccaddError(
                f"{path}: the mission expects event {name}, which its task does not raise"
            ) from None
    return LoadedMission(str(path), automaton, report, tuple(tasks), bits)


def _build(
    decl: A.TaskDecl,
    file: str,
    text: str,
    resource: PhysicalResource,
    registry: EventRegistry,
    queue: EventQueue,
) -> RobotTask:
    src = Path(decl.source)
    if not src.is_absolute():
        src = Path(file).parent / src
    spec = load_task_file(src)
    spec = replace(spec, task=replace(spec.task, name=decl.name))
    try:
        task = build_task(spec, resource, registry, queue)
    except OrccaddError as e:
        raise _err(decl.loc, text, f"task {decl.name}: {e}") from None
    for ps in decl.params:
        module = next(m for m in task.modules if m.name == ps.module)
        value = list(ps.value) if isinstance(ps.value, tuple) else ps.value
        try:
            module.configure({ps.param: value})
        except ParameterError as e:
            raise _err(ps.loc, text, f"task {decl.name}: {e}") from None
    return task
