"""Build a `RobotTask` from a `TaskSpec`: instantiate modules, check and bind the wiring,
order the schedule, and compile the reactive shell.

Every refusal names the task file, the key, and both ends of the wire (or the cycle).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from orccadd.errors import ConfigError, ParameterError, ResourceError, WiringError
from orccadd.modules import MODULES, Module, ModuleContext, Port, module_class
from orccadd.modules.base import Parameter
from orccadd.physres.base import PhysicalResource
from orccadd.task.events import (
    PRECONDITION_TIMEOUT,
    EventKind,
    EventQueue,
    EventRegistry,
)
from orccadd.task.spec import EventSpec, TaskSpec
from orccadd.task.task import Precondition, RobotTask, ShellEvent, TaskSignature
from orccadd.types import BUILTIN_T3, TASK_TIMEOUT, CommandMode

WIRE_RE = re.compile(r"^\s*(\w+)\.(\w+)\s*->\s*(\w+)\.(\w+)\s*$")
COMMAND_PORTS = {
    CommandMode.TORQUE: ("tau_cmd", "N.m"),
    CommandMode.VELOCITY: ("dq_cmd", "rad/s"),
    CommandMode.POSITION: ("q_cmd", "rad"),
}
MODE_BY_NAME = {
    "torque": CommandMode.TORQUE,
    "velocity": CommandMode.VELOCITY,
    "position": CommandMode.POSITION,
}


@dataclass
class _Node:
    name: str
    inputs: dict[str, Port]
    outputs: dict[str, Port]
    module: Module | None  # None for the resource
    optional: frozenset[str] = frozenset()  # inputs a task may leave unwired (a resource's commands)


def _resource_node(resource: PhysicalResource, mode: CommandMode, name: str) -> _Node:
    n = resource.dof
    outs = {}
    for port, unit, arr in (
        ("q", "rad", resource.state.q_rad),
        ("dq", "rad/s", resource.state.dq_rad_s),
        ("tau", "N.m", resource.state.tau_nm),
    ):
        p = Port(name, port, (n,), unit, np.float64, is_input=False)
        p.value = arr  # the measured state itself: no copy in a tick
        outs[port] = p
    for sig in resource.description.signals:  # the backend's own (e.g. the flange's wrench)
        p = Port(name, sig.name, (sig.size,), sig.unit, np.float64, is_input=False)
        p.value = resource.signals[sig.name]
        outs[sig.name] = p
    cmd_name, cmd_unit = COMMAND_PORTS[mode]
    ins = {cmd_name: Port(name, cmd_name, (n,), cmd_unit, np.float64, is_input=True)}
    for c in resource.description.commands:  # the backend's own (e.g. a UR's force mode)
        p = Port(name, c.name, (c.size,), c.unit, np.float64, is_input=True)
        p.value = resource.commands[c.name]
        ins[c.name] = p
    optional = frozenset(c.name for c in resource.description.commands)
    return _Node(name, ins, outs, None, optional)


def build_task(
    spec: TaskSpec,
    resource: PhysicalResource,
    registry: EventRegistry | None = None,
    queue: EventQueue | None = None,
) -> RobotTask:
    """Check and build the task for `resource`. Not for a tick (allocates everything)."""
    src = spec.source
    h = spec.task
    registry = registry if registry is not None else EventRegistry()
    queue = queue if queue is not None else EventQueue()
    # the file's `resource` is the resource's name in its wires; the mission binds the task to one
    # of the robot's resources (`task T on R`), this one
    wire_name = h.resource
    mode = MODE_BY_NAME[h.command]
    if mode not in resource.supported_modes:
        allowed = ", ".join(m.name.lower() for m in sorted(resource.supported_modes))
        raise ConfigError(
            src,
            "task.command",
            f"(={h.command!r}) is not supported by resource {resource.name!r} (supported: {allowed})",
        )
    try:  # the switch's first phase, here outside the tick: the loop performs it in one
        resource.prepare_mode_switch(mode)
    except ResourceError as e:
        raise ConfigError(src, "task.command", f"(={h.command!r}): {e}") from None
    joints = resource.model.joint_names
    for i, j in enumerate(h.joints):
        if j not in joints:
            raise ConfigError(
                src,
                f"task.joints[{i}]",
                f"(={j!r}) is not a joint of {resource.name!r} (joints: {', '.join(joints)})",
            )
    if h.joints and set(h.joints) != set(joints):
        raise ConfigError(
            src,
            "task.joints",
            "must name every joint of the resource: tasks on a subset of joints are not supported yet",
        )
    robot_period = resource.config.control_period_s
    period = h.period_s or robot_period
    decimation = round(period / robot_period)
    if decimation < 1 or abs(decimation * robot_period - period) > 1e-9:
        raise ConfigError(
            src,
            "task.period_s",
            f"(={h.period_s!r}) must be a whole multiple of the robot's control_period_s (={robot_period!r})",
        )
    ctx = ModuleContext(task=h.name, model=resource.model, period_s=period)
    nodes: dict[str, _Node] = {wire_name: _resource_node(resource, mode, wire_name)}
    modules: dict[str, Module] = {}
    for ms in spec.modules:
        key = f"modules.{ms.name}"
        if ms.name == wire_name:
            raise ConfigError(src, key, f"(={ms.name!r}) is the resource's name; choose another")
        cls = module_class(ms.type)
        if cls is None:
            raise ConfigError(
                src,
                f"{key}.type",
                f"(={ms.type!r}) is not a module type (known: {', '.join(sorted(MODULES))})",
            )
        m = cls(ms.name, ctx)
        try:
            m.configure(ms.parameters)
        except ParameterError as e:
            raise ConfigError(src, f"{key}.{e.name}", e.detail) from None
        modules[ms.name] = m
        nodes[ms.name] = _Node(ms.name, m.inputs, m.outputs, m)
    writers = _check_wires(spec, nodes)
    order = _schedule(spec, modules, writers, wire_name)
    for dst, srcp in writers.items():
        if dst.module == wire_name and dst.name in nodes[wire_name].optional:
            srcp.value = dst.value  # a resource's command: the module writes the resource's buffer
    for dst, srcp in writers.items():
        dst.value = srcp.value  # the input *is* the output buffer
    cmd_port = next(iter(nodes[wire_name].inputs.values()))
    events = _shell(spec, nodes, registry, modules)
    pres = []
    for i, p in enumerate(spec.preconditions):
        key = f"preconditions[{i}].signal"
        port = _find_port(spec, nodes, p.signal, key, output=True)
        if port.module != wire_name:  # checked before the modules run: measured signals only
            measured = ", ".join(f"{wire_name}.{n}" for n in nodes[wire_name].outputs)
            raise ConfigError(
                src,
                key,
                f"(={p.signal!r}) must be a measured signal ({measured}): "
                "preconditions are checked before the modules run",
            )
        lo, hi = p.within if p.within else (-np.inf, np.inf)
        pres.append(Precondition(p.name, port.value, p.timeout_s, p.max_abs_below, lo, hi))
    builtin = {name: registry.register(h.name, EventKind.T3, name) for name in BUILTIN_T3}
    timeout_s = h.timeout_s or resource.config.daemon.task_timeout_s
    t3_builtin: tuple[str, ...] = BUILTIN_T3
    if timeout_s != float("inf"):
        builtin[TASK_TIMEOUT] = registry.register(h.name, EventKind.T3, TASK_TIMEOUT)
        t3_builtin += (TASK_TIMEOUT,)
    t2 = [e.name for e in spec.events.T2]
    if spec.preconditions:
        builtin[PRECONDITION_TIMEOUT] = registry.register(h.name, EventKind.T2, PRECONDITION_TIMEOUT)
        builtin["pre"] = registry.register(h.name, EventKind.PRE, "pre")
        t2.append(PRECONDITION_TIMEOUT)
    sig = TaskSignature(
        name=h.name,
        resource=resource.name,
        joints=tuple(joints),
        command=mode,
        has_post=bool(spec.events.post),
        t1=tuple(e.name for e in spec.events.T1),
        t2=tuple(t2),
        t3=tuple(e.name for e in spec.events.T3) + t3_builtin,
        sync=tuple(e.name for e in spec.events.sync),
    )
    task = RobotTask(
        sig,
        resource,
        [modules[n] for n in order],
        cmd_port.value,
        pres,
        events,
        builtin,
        queue,
        decimation,
        period,
        timeout_s,
    )
    if resource.config.daemon.tick == "interpreted":  # the robot's [daemon] tick
        task.compiled = None
    return task


def _find_port(spec: TaskSpec, nodes: dict[str, _Node], ref: str, key: str, *, output: bool) -> Port:
    parts = ref.strip().split(".")
    if len(parts) != 2:
        raise ConfigError(spec.source, key, f"(={ref!r}) must be MODULE.PORT")
    node_name, port_name = parts
    node = nodes.get(node_name)
    if node is None:
        raise WiringError(
            f"{spec.source}: {key} (={ref!r}): no module {node_name!r} (modules: {', '.join(nodes)})"
        )
    ports = node.outputs if output else node.inputs
    if port_name not in ports:
        other = node.inputs if output else node.outputs
        kind = "output" if output else "input"
        hint = f"; {ref} is an {'input' if output else 'output'}" if port_name in other else ""
        raise WiringError(
            f"{spec.source}: {key} (={ref!r}): {node_name} has no {kind} {port_name!r} "
            f"({kind}s: {', '.join(ports) or 'none'}){hint}"
        )
    return ports[port_name]


def _check_wires(spec: TaskSpec, nodes: dict[str, _Node]) -> dict[Port, Port]:
    """Parse and check every wire; return input port -> output port."""
    src = spec.source
    writers: dict[Port, Port] = {}
    where: dict[Port, int] = {}
    for i, w in enumerate(spec.wires):
        key = f"wires[{i}]"
        m = WIRE_RE.match(w)
        if not m:
            raise ConfigError(src, key, f"(={w!r}) must read 'MODULE.OUTPUT -> MODULE.INPUT'")
        a = _find_port(spec, nodes, f"{m.group(1)}.{m.group(2)}", key, output=True)
        b = _find_port(spec, nodes, f"{m.group(3)}.{m.group(4)}", key, output=False)
        pre = f"{src}: {key} (={w.strip()!r}):"
        if a.dtype != b.dtype or a.shape != b.shape:
            raise WiringError(f"{pre} shape mismatch: {a.describe()} cannot feed {b.describe()}")
        if a.unit != b.unit:
            raise WiringError(
                f"{pre} unit mismatch: {a.path} is in {a.unit or 'no unit'}, "
                f"{b.path} expects {b.unit or 'no unit'}"
            )
        if b in writers:
            j = where[b]
            raise WiringError(
                f"{pre} {b.path} already has a writer: {writers[b].path} "
                f"(wires[{j}]); an input takes exactly one"
            )
        writers[b] = a
        where[b] = i
    for node in nodes.values():
        for port in node.inputs.values():
            if port not in writers and port.name not in node.optional:
                cands = [
                    o.path
                    for n in nodes.values()
                    for o in n.outputs.values()
                    if o.unit == port.unit and o.shape == port.shape and n is not node
                ]
                hint = f" (outputs that fit: {', '.join(cands)})" if cands else ""
                what = (
                    "the command input of the resource"
                    if node.module is None
                    else f"input of {node.module.type_name} {node.name!r}"
                )
                raise WiringError(f"{src}: {port.path} ({what}) is not connected{hint}")
    return writers


def _schedule(
    spec: TaskSpec, modules: dict[str, Module], writers: dict[Port, Port], resource_name: str
) -> list[str]:
    """Topological order of modules; the resource splits into source (read) and sink (write)."""
    deps: dict[str, set[str]] = {n: set() for n in modules}
    via: dict[tuple[str, str], str] = {}
    for dst, srcp in writers.items():
        if dst.module == resource_name or srcp.module == resource_name:
            continue
        deps[dst.module].add(srcp.module)
        via[(srcp.module, dst.module)] = f"{srcp.path} -> {dst.path}"
    order: list[str] = []
    done: set[str] = set()
    visiting: list[str] = []

    def visit(n: str) -> None:  # depth-first, dependencies first
        if n in done:
            return
        if n in visiting:
            # visiting[i] depends on visiting[i+1]: reverse to print in signal-flow order
            cycle = [*visiting[visiting.index(n) :], n][::-1]
            wires = ", ".join(via[(cycle[k], cycle[k + 1])] for k in range(len(cycle) - 1))
            raise WiringError(
                f"{spec.source}: algebraic loop {' -> '.join(cycle)} ({wires}): "
                "break it with a module that delays by one tick"
            )
        visiting.append(n)
        for d in sorted(deps[n]):
            visit(d)
        visiting.pop()
        done.add(n)
        order.append(n)

    for n in modules:
        visit(n)
    return order


def _shell(
    spec: TaskSpec, nodes: dict[str, _Node], registry: EventRegistry, modules: dict[str, Module]
) -> list[ShellEvent]:
    src, h = spec.source, spec.task
    out: list[ShellEvent] = []

    def flag_of(e_when: str, key: str) -> Port:
        port = _find_port(spec, nodes, e_when, key, output=True)
        if port.dtype != np.bool_ or port.shape != ():
            raise WiringError(
                f"{src}: {key} (={e_when!r}): {port.describe()} is not an event "
                "(a watcher's boolean 'fired' output is)"
            )
        return port

    if spec.events.post:
        port = flag_of(spec.events.post, "events.post")
        out.append(
            ShellEvent(
                "done",
                EventKind.POST,
                registry.register(h.name, EventKind.POST, "done"),
                port.value,
                (),
            )
        )
    groups: tuple[tuple[str, EventKind, tuple[EventSpec, ...]], ...] = (
        ("T1", EventKind.T1, spec.events.T1),
        ("T2", EventKind.T2, spec.events.T2),
        ("T3", EventKind.T3, spec.events.T3),
        ("sync", EventKind.SYNC, spec.events.sync),
    )
    for label, kind, specs in groups:
        for i, e in enumerate(specs):
            key = f"events.{label}[{i}]"
            if kind is EventKind.T3 and e.name in (*BUILTIN_T3, TASK_TIMEOUT):
                raise ConfigError(src, f"{key}.name", f"(={e.name!r}) is a built-in type 3 exception")
            port = flag_of(e.when, f"{key}.when")
            reaction: list[tuple[Module, Parameter, np.ndarray]] = []
            if kind is EventKind.T1:
                if not e.set:
                    raise ConfigError(
                        src,
                        f"{key}.set",
                        "is missing: a type 1 exception needs a local "
                        'reaction, e.g. set = { "traj.speed_scale" = 0.5 }',
                    )
                for pkey, value in e.set.items():
                    mod_name, _, pname = pkey.partition(".")
                    mod = modules.get(mod_name)
                    if mod is None or pname not in mod.parameters:
                        raise ConfigError(src, f"{key}.set.{pkey}", "names no parameter (MODULE.PARAM)")
                    param = mod.parameters[pname]
                    if not param.tunable:
                        raise ConfigError(src, f"{key}.set.{pkey}", "is not tunable at run time")
                    try:
                        reaction.append((mod, param, param.check(value)))
                    except ParameterError as err:
                        raise ConfigError(src, f"{key}.set.{pkey}", err.detail) from None
            out.append(
                ShellEvent(e.name, kind, registry.register(h.name, kind, e.name), port.value, reaction)
            )
    return out
