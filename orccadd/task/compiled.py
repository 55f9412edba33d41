"""The compiled tick: a task's schedule and shell as one generated function, as ORCCAD generated
code from the block diagram.

`compile_schedule(task)` writes the Python source of the part of a tick between the resource's
read and the command: each module's kernel (`Module.kernel`) called in schedule order with its
inputs' values bound as locals (the measured q, dq, tau read from the resource once, as lists),
the shell's events tested on those locals, the command written into the task's command buffer.
No port buffer is read or written in between, no dictionary or attribute looked up per module.
A module without a kernel is called through its `update`: the locals it reads are written into
its input buffers first, and its outputs are read from their buffers where they are needed.

At the end, the kernels' outputs are written into their ports, so that the ports hold what they
hold after an interpreted tick (a tuned module, a monitor or a test reads them). Both paths run
the same kernels: their commands are bit-identical (tests/task/test_compiled.py runs both).
`RobotTask.compiled = None` selects the interpreted path (each `update` on its ports).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from orccadd.modules.base import Module


class _Task(Protocol):  # what is compiled of a `RobotTask`
    @property
    def name(self) -> str: ...
    @property
    def modules(self) -> Sequence[Module]: ...
    @property
    def command(self) -> Any: ...
    @property
    def events(self) -> Sequence[Any]: ...

    def emit_event(self, t_s: float, ev: Any) -> None: ...


class _Writer:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.ns: dict[str, Any] = {}
        self.local: dict[int, str] = {}  # id(buffer) -> the local holding its value this tick
        self.stale: dict[int, Any] = {}  # buffers whose value is only in their local (kernel outputs)
        self.module_at: dict[int, str] = {}  # source line -> the module it runs

    def bind(self, prefix: str, obj: Any) -> str:
        name = f"{prefix}{len(self.ns)}"
        self.ns[name] = obj
        return name

    def emit(self, line: str) -> None:
        self.lines.append("    " + line)

    def value(self, buf: Any) -> str:
        """The local holding `buf`'s value (read from the buffer the first time it is needed)."""
        key = id(buf)
        name = self.local.get(key)
        if name is None:
            b = self.bind("b", buf)
            name = self.local[key] = f"v{len(self.local)}"
            self.emit(f"{name} = {b}.tolist()")
        return name

    def flush(self, buf: Any) -> None:
        """Make the buffer hold its value (a kernel's output read by an `update` or a command)."""
        key = id(buf)
        if key in self.stale:
            self.emit(f"{self.bind('b', buf)}[...] = {self.local[key]}")
            del self.stale[key]


class CompiledTick:
    """The generated function (`run`), its source, and which module each of its lines runs (a
    traceback through it names the module, as through the interpreted schedule)."""

    def __init__(self, run: Callable[[float], None], source: str, module_at: dict[int, str]) -> None:
        self.run = run
        self.source = source
        self.module_at = module_at


def compile_schedule(task: _Task) -> CompiledTick:
    """The task's modules and shell events as one function of t_s."""
    w = _Writer()
    for m in task.modules:
        k = m.kernel()
        if k is None:
            for p in m.inputs.values():
                w.flush(p.value)
            w.module_at[len(w.lines) + 2] = m.name
            w.emit(f"{w.bind('update', m.update)}(t_s)")
            for p in m.outputs.values():  # in the buffer now: read from it when needed
                w.local.pop(id(p.value), None)
            continue
        args = "".join(f", {w.value(p.value)}" for p in m.inputs.values())
        outs = []
        for p in m.outputs.values():
            name = f"o{len(w.local)}"
            w.local[id(p.value)] = name
            w.stale[id(p.value)] = p.value
            outs.append(name)
        w.module_at[len(w.lines) + 2] = m.name  # (line 1 is the def)
        w.emit(f"{', '.join(outs)}, = {w.bind('kernel', k)}(t_s{args})  # {m.name}")
    for buf in list(w.stale.values()):  # the ports hold their values, as after an interpreted tick
        w.flush(buf)
    emit = w.bind("emit", task.emit_event)
    for ev in task.events:
        e, fired = w.bind("event", ev), w.value(ev.flag)
        w.emit(f"if {fired} and not {e}.prev:")
        w.emit(f"    {emit}(t_s, {e})")
        w.emit(f"{e}.prev = {fired}")
    body = w.lines or ["    pass"]
    source = "\n".join(["def compiled_tick(t_s):", *body]) + "\n"
    exec(compile(source, f"<compiled tick of task {task.name}>", "exec"), w.ns)
    return CompiledTick(w.ns["compiled_tick"], source, w.module_at)
