"""What a mission must pass before the daemon runs it: one function for `orccadctl check` and
for the daemon's `load`, and the tasks built against a robot (`build_mission_tasks`: the daemon's
`load`, and `orccadctl check --config ROBOT`).

Compile (parse, elaborate, build the automaton: `MissionError` at file:line:col), then the
verifier's checks with the execution machine's own (one Robot-Task active at a time on each
resource, every task
from a task file): the `Report`, whose failures the caller refuses with their counterexamples.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

from orccadd.automaton import Automaton, Network, Report, compile_file, compile_text, verify, verify_network
from orccadd.automaton.checks.verify import CheckResult
from orccadd.automaton.compiler.explicit import DEFAULT_MAX_STATES, Progress
from orccadd.automaton.language import ast as A
from orccadd.automaton.language.program import Program
from orccadd.config.robot import MAX_TOML_BYTES
from orccadd.confine import Confinement
from orccadd.errors import ConfigError, MissionError, OrccaddError, ParameterError, did_you_mean
from orccadd.model import RobotModel
from orccadd.modules import MODULES, ModuleContext, module_class
from orccadd.physres.base import PhysicalResource
from orccadd.task import EventQueue, EventRegistry, RobotTask, build_task, load_task_file
from orccadd.task.events import EventKind
from orccadd.task.spec import TaskSpec, interface_of, parse_task_text
from orccadd.types import TaskInterface


class TaskFiles:
    """The task files a mission names, each read once: its interface for the compiler
    (`interface`, a `TaskFileReader`), its spec for building the task (`spec`). With a
    `Confinement`, only files inside its directories are read, each by a checked descriptor
    (the daemon's `load`); without, any file the caller may read (`orccadctl check`)."""

    def __init__(self, confinement: Confinement | None = None) -> None:
        self.confinement = confinement
        self.specs: dict[str, TaskSpec] = {}
        self.digests: dict[str, str] = {}  # the SHA-256 of each file read through `confinement`

    def spec(self, path: Path) -> TaskSpec:
        key = str(path)
        if key not in self.specs:
            if self.confinement is None:
                self.specs[key] = load_task_file(path)
            else:
                try:
                    data, _ = self.confinement.read(path, MAX_TOML_BYTES)
                except OrccaddError as e:
                    raise ConfigError(key, "", str(e).removeprefix(f"{key}: ")) from None
                self.digests[key] = hashlib.sha256(data).hexdigest()
                self.specs[key] = parse_task_text(data, key)
        return self.specs[key]

    def interface(self, path: Path) -> TaskInterface:
        return interface_of(self.spec(path))


def check_mission(
    path: str | Path,
    max_states: int = DEFAULT_MAX_STATES,
    progress: Progress | None = None,
    text: str | None = None,
    task_files: TaskFiles | None = None,
) -> tuple[Automaton | Network, Report]:
    """The compiled mission and its verification report; `MissionError` if it does not compile.
    A mission whose main procedure runs a large `par` of independent branches compiles as a
    network (`orccadd.automaton.compiler.network`), checked on its products (`verify_network`).
    `text`: the mission's content, already read from `path` (the daemon reads it by descriptor);
    `task_files`: how its task files are read (default: any file, by path)."""
    files = task_files or TaskFiles()
    automaton: Automaton | Network
    if text is None:
        automaton = compile_file(path, max_states, files.interface, progress, allow_network=True)
    else:
        automaton = compile_text(text, str(path), max_states, files.interface, progress, allow_network=True)
    if isinstance(automaton, Network):
        report = verify_network(automaton, one_task_per_resource=True, max_states=max_states)
    else:
        report = verify(automaton, one_task_per_resource=True)
    report.results.append(_check_task_files(automaton))
    return automaton, report


def _check_task_files(automaton: Automaton | Network) -> CheckResult:
    bare = [f"{d.name} (line {d.loc.line})" for d in automaton.program.ast.tasks if not d.source]
    if bare:
        return CheckResult(
            "task files", False, f"no task file for {', '.join(bare)}",
            explanation='the daemon runs tasks declared `from "file.toml"` only',
        )  # fmt: skip
    return CheckResult("task files", True, "every task is built from a task file")


Bindings = Mapping[str, tuple[PhysicalResource, EventQueue]]  # resource name → it, its loop's events


def build_mission_tasks(
    automaton: Automaton | Network,
    bindings: Bindings,
    registry: EventRegistry,
    task_spec: Callable[[Path], TaskSpec] = load_task_file,
    data: Mapping[str, object] | None = None,
) -> tuple[tuple[RobotTask, ...], dict[int, int]]:
    """Every task of a compiled mission built for the robot's resource it runs on (`bindings`:
    by name, each with the event queue of its control loop; modules instantiated, ports bound,
    the mission's `set` lines applied), and event registry id → the automaton's input bit.
    `MissionError` at the task's or `set` line's place, `OrccaddError` otherwise. `task_spec`
    gives a task file's spec (default: read it; the daemon: the specs its compiler read).
    `data`: what modules take beyond their parameters (`Module.set_data`), by `TASK.MODULE`
    (the daemon's: a trajectory `orccadctl follow` sent). Needs no hardware: the resources are
    built, not configured. Not for a tick."""
    p = automaton.program
    text = p.text
    have = ", ".join(f"`{n}`" for n in bindings)
    for decl in p.ast.tasks:
        if decl.resource not in bindings:
            what = "resource is" if len(bindings) == 1 else "resources are"
            raise _err(
                decl.loc, text, f"task {decl.name} runs on `{decl.resource}`, but this robot's {what} {have}"
            )
    given = dict(data or {})
    tasks = tuple(
        _build(decl, p.file, text, *bindings[decl.resource], registry, task_spec, given)
        for decl in p.ast.tasks
    )
    if given:
        raise OrccaddError(f"{p.file}: data for {', '.join(sorted(given))}, which the mission does not have")
    bits: dict[int, int] = {}
    for i, name in enumerate(p.inputs):
        if p.input_kind[i] == "operator" and "." in name:  # a resource's input, `R.X`
            bits[_resource_io(p, name, bindings, "input", registry)] = 1 << i
        if p.input_task[i] < 0:
            continue
        try:
            bits[registry.id(name)] = 1 << i
        except KeyError:
            raise OrccaddError(
                f"{p.file}: the mission expects event {name}, which its task does not raise"
            ) from None
    for name in p.internals:
        if "." in name:
            _resource_io(p, name, bindings, "output", registry)
    return tasks, bits


def _resource_io(p: Program, name: str, bindings: Bindings, what: str, registry: EventRegistry) -> int:
    """`R.X`, a resource's named input (registered: its event id) or output action (checked)
    against the robot's resource R; a `MissionError` at its declaration otherwise."""
    r, x = name.split(".", 1)
    decl = next(d for d in (*p.ast.inputs, *p.ast.signals) if d.name == name)
    if r not in bindings:
        raise _err(
            decl.loc, p.text, f"`{name}`: this robot has no resource `{r}` (it has {', '.join(bindings)})"
        )
    resource = bindings[r][0]
    have = resource.description.inputs if what == "input" else resource.description.outputs
    if x not in have:
        table = "digital_inputs" if what == "input" else "digital_outputs"
        listed = ", ".join(have) or "none"
        raise _err(
            decl.loc, p.text,
            f"`{name}`: resource `{r}` has no {what} `{x}` (its {what}s: {listed}; a `ur_rtde` arm names "
            f"them in [resource.settings] {table})",
        )  # fmt: skip
    return registry.register(r, EventKind.INPUT, x) if what == "input" else -1


def _err(decl_loc: A.Loc, text: str, msg: str) -> MissionError:
    return MissionError(decl_loc.file, decl_loc.line, decl_loc.col, msg, text)


def _build(
    decl: A.TaskDecl,
    file: str,
    text: str,
    resource: PhysicalResource,
    queue: EventQueue,
    registry: EventRegistry,
    task_spec: Callable[[Path], TaskSpec],
    data: dict[str, object],
) -> RobotTask:
    src = Path(decl.source)
    if not src.is_absolute():
        src = Path(file).parent / src
    spec = task_spec(src)
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
    for m in task.modules:
        key = f"{decl.name}.{m.name}"
        try:
            if key in data:
                m.set_data(data.pop(key))
        except ParameterError as e:
            raise _err(decl.loc, text, f"task {decl.name}: {e}") from None
        if m.needs_data():
            raise _err(
                decl.loc, text,
                f"task {decl.name}: module {m.name} ({m.type_name}) plays data the daemon gives it "
                "(a trajectory: `orccadctl follow`), which a mission file cannot",
            )  # fmt: skip
    missing = [f"{m.name}.{name}" for m in task.modules for name in m.missing()]
    if missing:
        first = missing[0]
        raise _err(
            decl.loc,
            text,
            f"task {decl.name}: {', '.join(missing)} required, and set neither in {src.name} "
            f"(modules.{first}) nor by the mission (`set {first} = ...`)",
        )
    return task


def check_on_robot(
    automaton: Automaton | Network, resources: Sequence[PhysicalResource], robot: str
) -> CheckResult:
    """Whether every task of the mission builds on this robot (`orccadctl check --config`):
    a misspelt module parameter, a missing gain or a joint the robot lacks, before `load`."""
    try:
        bindings = {r.name: (r, EventQueue()) for r in resources}
        tasks, _ = build_mission_tasks(automaton, bindings, EventRegistry())
    except OrccaddError as e:
        return CheckResult(f"robot {robot}", False, str(e).splitlines()[0], explanation=_rest(e))
    built = ", ".join(f"{t.name} on {t.resource.name} ({len(t.modules)} modules)" for t in tasks)
    return CheckResult(f"robot {robot}", True, f"every task builds: {built}")


def _rest(e: OrccaddError) -> str:
    return "\n       ".join(str(e).splitlines()[1:])


def check_parameter_names(automaton: Automaton | Network, model: RobotModel) -> CheckResult:
    """Every task's module types and parameter names, in its task file and in the mission's
    `set` lines. They do not depend on the robot, so `orccadctl check` runs this one with no
    robot too: `model` (a stand-in's, when there is no robot) only sizes the modules; values,
    shapes, bounds and joints are load's checks on the robot."""
    p = automaton.program
    ctx = ModuleContext(task="check", model=model, period_s=STAND_IN_PERIOD_S)
    for decl in p.ast.tasks:
        if not decl.source:
            continue
        src = Path(decl.source) if Path(decl.source).is_absolute() else Path(p.file).parent / decl.source
        try:
            spec = load_task_file(src)
            known = {ms.name: _parameter_names(ms.name, ms.type, ctx, src) for ms in spec.modules}
            for ms in spec.modules:
                for key in ms.parameters:
                    _known_name(known[ms.name], ms.name, key, f"{src}: modules.{ms.name}.{key}")
        except OrccaddError as e:
            return CheckResult("parameter names", False, f"task {decl.name}: {e}")
        for ps in decl.params:
            where = f"{ps.loc.file}:{ps.loc.line}:{ps.loc.col}: task {decl.name}: {ps.module}.{ps.param}"
            try:
                if ps.module not in known:
                    raise OrccaddError(f"{where}: no module {ps.module!r} (modules: {', '.join(known)})")
                _known_name(known[ps.module], ps.module, ps.param, where)
            except OrccaddError as e:
                return CheckResult("parameter names", False, str(e))
    return CheckResult("parameter names", True, "every module type and parameter name is known")


STAND_IN_PERIOD_S = 0.002  # sizes nothing a name depends on


def _parameter_names(name: str, type_name: str, ctx: ModuleContext, src: Path) -> set[str] | None:
    """The parameter names of module type `type_name`; None where it cannot be built on the
    stand-in robot (its names are then load's to check)."""
    cls = module_class(type_name)
    if cls is None:
        known = ", ".join(sorted(MODULES))
        raise OrccaddError(
            f"{src}: modules.{name}.type (={type_name!r}) is not a module type (known: {known})"
        )
    try:
        return set(cls(name, ctx).parameters)
    except (OrccaddError, ValueError, IndexError):
        return None


def _known_name(known: set[str] | None, module: str, key: str, where: str) -> None:
    if known is not None and key not in known:
        raise OrccaddError(
            f"{where} is not a parameter of {module}{did_you_mean(key, known)} "
            f"(parameters: {', '.join(sorted(known)) or 'none'})"
        )
