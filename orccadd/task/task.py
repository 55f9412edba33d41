"""A built Robot-Task: a flat schedule of module updates inside its reactive shell.

One `tick(t_s)` is the hot path: read the resource, check preconditions or run the schedule,
evaluate the shell's events (`compute`), write the command (`commit`): the daemon's loop may
switch to another task between the two halves, whose law then commands this very tick. It
allocates no buffers and raises nothing; a type 3 exception calls `resource.safe_stop()` right
there, before anyone else hears of it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from orccadd.errors import ParameterError, did_you_mean
from orccadd.fault import Fault, FaultKind
from orccadd.modules.base import CommandMotion, Module, Parameter
from orccadd.physres.base import PhysicalResource
from orccadd.physres.torque_hold import TorqueHold
from orccadd.task.compiled import CompiledTick, compile_schedule
from orccadd.task.events import EventKind, EventQueue
from orccadd.task.motion import CommandHistory, extrapolate
from orccadd.types import T3_MASK, TASK_TIMEOUT, CommandMode, Phase, Status
from orccadd.vec import float_view, max_of, min_of

# the kind of each built-in type 3 exception; those a resource raises take the resource's own
# fault (its words, joint and code) when it is of a matching kind
BUILTIN_FAULT_KINDS = {
    "LimitViolation": FaultKind.LIMIT,
    "ResourceFault": FaultKind.DEVICE,
    "CommLost": FaultKind.COMM_LOST,
    "Overrun": FaultKind.OVERRUN,
    "LawError": FaultKind.INTERNAL,
    TASK_TIMEOUT: FaultKind.TIMEOUT,
}
RESOURCE_T3 = {
    "LimitViolation": (FaultKind.LIMIT, FaultKind.COMMAND),
    "ResourceFault": (FaultKind.DEVICE,),
    "CommLost": (FaultKind.COMM_LOST,),
}

log = logging.getLogger("orccadd.task")

RUNNING = (Phase.RUN, Phase.DONE, Phase.ABORTED)
# the phases each tick compares with, as module globals (an IntEnum member's lookup costs ~0.1 µs)
PRE, FAULT = Phase.PRE, Phase.FAULT


class ParameterChange(NamedTuple):
    """A checked parameter value, ready to be written in place at a tick boundary."""

    module: Module
    param: Parameter
    value: npt.NDArray[np.float64]  # the whole parameter, or the one element at `element`
    element: int | None = None  # `PARAM[i]`: only that element is written


def split_index(path: str) -> tuple[str, int | None]:
    """`traj.target_rad[2]` → (`traj.target_rad`, 2); a path without `[i]` → (path, None).
    `ParameterError` for a malformed index."""
    if not path.endswith("]"):
        return path, None
    name, sep, rest = path[:-1].partition("[")
    if not sep or not rest.isdigit() or len(rest) > 6:
        raise ParameterError(f"{path!r}: an element is named PARAM[i], i a joint's index from 0")
    return name, int(rest)


@dataclass(frozen=True)
class TaskSignature:
    """The abstract view of a task (seed figure 1): what the procedure language sees."""

    name: str
    resource: str
    joints: tuple[str, ...]
    command: CommandMode
    has_post: bool
    t1: tuple[str, ...]
    t2: tuple[str, ...]
    t3: tuple[str, ...]
    sync: tuple[str, ...]


class Precondition:
    """A test on a measured signal that must hold before the law starts, within `timeout_s`."""

    __slots__ = ("hi", "lo", "max_abs", "name", "scratch", "signal", "timeout_s")

    def __init__(
        self,
        name: str,
        signal: npt.NDArray[np.float64],
        timeout_s: float,
        max_abs: float,
        lo: float,
        hi: float,
    ) -> None:
        self.name = name
        self.signal = signal
        self.timeout_s = timeout_s
        self.max_abs = max_abs
        self.lo = lo
        self.hi = hi
        self.scratch = np.zeros_like(signal)

    def holds(self) -> bool:
        s = self.signal
        np.abs(s, out=self.scratch)
        if max_of(self.scratch) >= self.max_abs:
            return False
        return min_of(s) >= self.lo and max_of(s) <= self.hi


class ShellEvent:
    """One event of the shell: a watcher's `fired` flag, its kind, id and T1 reaction."""

    __slots__ = ("event_id", "flag", "kind", "name", "prev", "reaction")

    def __init__(
        self,
        name: str,
        kind: EventKind,
        event_id: int,
        flag: npt.NDArray[np.bool_],
        reaction: Sequence[tuple[Module, Parameter, npt.NDArray[np.float64]]],
    ) -> None:
        self.name = name
        self.kind = kind
        self.event_id = event_id
        self.flag = flag
        self.prev = False
        self.reaction = tuple(reaction)


class RobotTask:
    """A Robot-Task ready to run on its resource. Build it with `orccadd.task.build_task`."""

    def __init__(
        self,
        signature: TaskSignature,
        resource: PhysicalResource,
        modules: Sequence[Module],
        command: npt.NDArray[np.float64],
        preconditions: Sequence[Precondition],
        events: Sequence[ShellEvent],
        builtin_ids: dict[str, int],
        queue: EventQueue,
        decimation: int,
        period_s: float,
        timeout_s: float = float("inf"),
    ) -> None:
        self.signature = signature
        self.name = signature.name
        self.resource = resource
        self.modules = tuple(modules)
        self.schedule: tuple[Callable[[float], None], ...] = tuple(m.update for m in modules)
        self.command = command
        self.preconditions = tuple(preconditions)
        self.events = tuple(events)
        self.builtin_ids = builtin_ids
        self.queue = queue
        self.decimation = decimation
        self.period_s = period_s
        self.timeout_s = timeout_s  # of the law's run: then the type 3 `Timeout` (inf: never)
        self.phase = Phase.IDLE
        self.ticks = 0
        self.t_started_s = 0.0
        self.last_write_flags = 0
        self.fault_reason = ""
        self.fault: Fault | None = None  # what its last type 3 exception was about
        # the resource's type 3 status flags (`T3_MASK`) already raised as a type 3 while the
        # resource is safe-stopped for it: by this task, or by the one before it (the switch hands
        # them over). A task does not raise them again: one stop, one type 3, until a reset
        self.reported_t3 = 0
        self._pre_started = False
        self._tunable = {f"{m.name}.{p.name}": (m, p) for m in modules for p in m.parameters.values()}
        # bumpless transfer: the first command continues the previous task's last one
        self.sent = np.zeros_like(command)  # the last command sent (after blending)
        # the law's command and `sent` as memoryviews: each tick copies one into the other, in a
        # third of numpy's time
        self._command_view, self._sent_view = float_view(command), float_view(self.sent)
        self.wrote = False  # a command was sent in the last tick
        self.wrote_before = False  # the same, of the tick before (while `compute` runs)
        self._offset = np.zeros_like(command)
        self._blended = np.zeros_like(command)
        self._blend_ticks = 0
        self._blend_left = 0
        self._holding_previous = False
        # a torque task waiting for its preconditions after a switch holds the arm (TorqueHold)
        full = len(command) == resource.model.dof
        torque = signature.command is CommandMode.TORQUE and full
        self._torque_hold = TorqueHold(resource.model) if torque else None
        # position commands: a blend never steps faster than the joints may move (the resource
        # would clamp that step as a limit violation); 0.9 of it, per robot period
        position = signature.command is CommandMode.POSITION
        model, robot_period_s = resource.model, resource.config.control_period_s
        self._robot_period_s = robot_period_s  # a switched-to task's first command: a tick later
        self._blend_step_rad: list[float] = (
            (model.v_max_rad_s * robot_period_s * 0.9).tolist() if position else []
        )
        # position commands: the last ones sent, whose motion a task switched to continues (its
        # modules start from it, `Module.continued`; the blend from where it goes on to)
        self._history = CommandHistory(len(command), period_s) if position and full else None
        self._motion = CommandMotion(len(command))  # the outgoing command's, from `continue_from`
        self._continuing = False
        self._out: npt.NDArray[np.float64] | None = None  # compute's command, for commit
        # the schedule and the shell's events as one generated function (None: interpreted)
        self.compiled: Callable[[float], None] | None = None
        self.compiled_tick: CompiledTick | None = None
        self.recompile()

    # ---- control (not for a tick unless said) ---------------------------------------------
    def recompile(self) -> None:
        """Generate the compiled tick again (after a module's kernel was replaced)."""
        self.compiled_tick = compile_schedule(self)
        self.compiled = self.compiled_tick.run

    def activate(self) -> None:
        """Arm the task: the next tick checks preconditions (or starts the law at once)."""
        self.phase = Phase.PRE
        self.ticks = 0
        self.fault_reason = ""
        for ev in self.events:
            ev.prev = False
        self._pre_started = False
        self._holding_previous = False
        self._blend_left = 0
        self._continuing = False
        self.reported_t3 = 0
        if self._history is not None:
            self._history.clear()

    def command_motion(self, out: CommandMotion) -> bool:
        """The motion of this task's position command (`CommandHistory.motion`) into `out`;
        False for a task not commanding positions for every joint, or that sent none since it
        was activated. Tick-safe."""
        return self._history is not None and self._history.motion(out)

    def continue_from(
        self, previous: npt.NDArray[np.float64], blend_ticks: int, motion: CommandMotion | None = None
    ) -> None:
        """Switching (seed §5.1): until the law starts, keep sending `previous` (the outgoing
        task's last command) — for a torque task, a hold (`TorqueHold`: the outgoing law's last
        torque is a stale feed-forward on a moving arm, and no watcher of this task runs before
        its law does); then blend the difference between it and this law's first command out
        linearly over `blend_ticks`, so the command never jumps. `motion`: the outgoing position
        command's (`command_motion`), for a position task: its modules start from it
        (`Module.continued`) and the blend from where it goes on to, so the command keeps its
        velocity too. Call after `activate`."""
        self.sent[:] = previous
        if motion is not None and self._history is not None:
            m = self._motion
            m.q_rad[:] = motion.q_rad
            m.dq_rad_s[:] = motion.dq_rad_s
            m.ddq_rad_s2[:] = motion.ddq_rad_s2
            self._continuing = True
        self._holding_previous = True
        if self._torque_hold is not None:
            self._torque_hold.release()  # held where the arm is when the wait begins
        self._blend_ticks = self._blend_left = max(0, blend_ticks)

    def deactivate(self) -> None:
        self.phase = Phase.IDLE
        self.wrote = False

    @property
    def tunable_names(self) -> list[str]:
        """`MODULE.PARAM` of every parameter `tune` may name, sorted (the trace numbers them so)."""
        return sorted(self._tunable)

    def prepare_tune(self, path: str, value: Any) -> ParameterChange:
        """Check `MODULE.PARAM = value`, or `MODULE.PARAM[i] = number` for one element of a
        vector (name, tunable, index, bounds, shape), without applying it. `ParameterError` says
        what is wrong. Not for a tick."""
        name, index = split_index(path)
        if name not in self._tunable:
            known = sorted(self._tunable)
            raise ParameterError(
                f"task {self.name} has no parameter {name!r}{did_you_mean(name, known)} "
                f"(parameters: {', '.join(known)})"
            )
        module, param = self._tunable[name]
        if not param.tunable:
            raise ParameterError(f"{self.name}.{name} is not tunable at run time")
        if index is None:
            return ParameterChange(module, param, param.check(value))
        n = param.shape[0] if param.shape else 0
        if not 0 <= index < n:
            what = f"indices 0 to {n - 1}" if n else "no index: it is one number"
            raise ParameterError(f"{self.name}.{path}: {name} has {what}")
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise ParameterError(f"{self.name}.{path} (={value!r}) must be one number")
        whole = param.value.copy()
        whole[index] = value
        return ParameterChange(module, param, param.check(whole)[index : index + 1], index)

    def tune(self, path: str, value: Any) -> None:
        """Check and apply at once: only for a task no thread is ticking (the daemon hands a
        running task's changes to its control thread, which applies them at a tick boundary)."""
        self.apply_change(self.prepare_tune(path, value))

    @staticmethod
    def apply_change(change: ParameterChange) -> None:
        """Write a checked change into its parameter (tick-safe: an in-place copy)."""
        if change.element is None:
            change.param.value[...] = change.value
        else:
            change.param.value[change.element] = change.value[0]
        change.module.on_parameter_change(change.param.name)

    def parameters(self) -> list[dict[str, Any]]:
        return [p.describe() for _, p in self._tunable.values()]

    def raise_t3(self, t_s: float, name: str, text: str = "") -> None:
        """A type 3 exception from outside the task (e.g. the executor's overrun count), `text`
        saying why. Tick-safe (the rare path: allocates)."""
        if self.phase is Phase.FAULT:
            return
        self.resource.safe_stop()
        self.phase = Phase.FAULT
        self.fault_reason = name
        self.fault = self._fault_for(name, text)
        self.queue.push(t_s, self.builtin_ids[name])

    def _fault_for(self, name: str, text: str) -> Fault:
        res = self.resource
        kind = BUILTIN_FAULT_KINDS.get(name)
        if kind is None:  # one the task file declares (a watcher's)
            return Fault(FaultKind.MISSION, res.name, text or f"{self.name} raised {name}")
        if name in RESOURCE_T3 and res.fault is not None and res.fault.kind in RESOURCE_T3[name]:
            return res.fault  # the device's own words, joint and code
        return Fault(kind, res.name, text or f"{name} (no device message)")

    # ---- the hot path ---------------------------------------------------------------------
    def tick(self, t_s: float) -> None:
        """One period: read → preconditions or law → shell events → write (or keep_alive).
        An exception (a module's or a backend's bug) is the type 3 `LawError`: the arm is
        safe-stopped in this tick, the loop goes on."""
        self.compute(t_s)
        self.commit(t_s)

    def compute(self, t_s: float, read: bool = True) -> None:
        """The first half of a tick: read the resource (`read=False`: take the state this tick
        has read already, for a task switched to within the tick), check the preconditions or
        run the law, raise the shell's events. The command waits for `commit`."""
        self._out = None
        self.wrote_before, self.wrote = self.wrote, False
        try:
            self._compute(t_s, read)
        except Exception as e:
            self._law_error(t_s, e)

    def run_law(self, t_s: float) -> None:
        """The law's modules in schedule order, then the shell's events: compiled, or
        interpreted (`compiled = None`: each module's update on its ports)."""
        compiled = self.compiled
        if compiled is not None:
            compiled(t_s)
            return
        for update in self.schedule:
            update(t_s)
        for ev in self.events:
            fired = bool(ev.flag)
            if fired and not ev.prev:
                self.emit_event(t_s, ev)
            ev.prev = fired

    def commit(self, t_s: float) -> None:
        """The second half: send the command `compute` prepared (or keep the device alive)."""
        out = self._out
        if out is not None:
            self._out = None
            try:
                self._send(t_s, out)
            except Exception as e:
                self._law_error(t_s, e)
        if not self.wrote:
            self.resource.keep_alive(t_s)

    def _law_error(self, t_s: float, error: Exception) -> None:
        where = self.name
        tb = error.__traceback__
        compiled = self.compiled_tick
        while tb is not None:  # the innermost module the exception came through
            frame = tb.tb_frame
            obj = frame.f_locals.get("self")
            if isinstance(obj, Module):
                where = f"{self.name}.{obj.name}"
            elif compiled is not None and frame.f_code is compiled.run.__code__:
                where = f"{self.name}.{compiled.module_at.get(tb.tb_lineno, '')}".rstrip(".")
            tb = tb.tb_next
        self.wrote = False
        why = f"{where}: {type(error).__name__}: {error}"
        self.raise_t3(t_s, "LawError", why)
        self.fault_reason = f"LawError: {why}"
        log.error("%s (at t = %.3f s): the arm is safe-stopped", self.fault_reason, t_s, exc_info=error)

    def _compute(self, t_s: float, read: bool) -> None:
        res = self.resource
        st = res.read(t_s) if read else res.state
        if st.status & T3_MASK:
            if st.status & T3_MASK & ~self.reported_t3 or not res.stopping_or_stopped:
                self._resource_t3(t_s, st.status)
            return  # (already stopped for it: a task before this one raised it)
        phase = self.phase
        if phase is PRE:
            if not self._pre_started:
                self._pre_started = True
                self.t_started_s = t_s
            if not self._preconditions_hold(t_s):
                if self._holding_previous and self.phase is Phase.PRE:
                    if self._torque_hold is not None:
                        self._torque_hold.update(st, self.sent)
                    self._out = self.sent  # the outgoing command (a torque: a hold), until the law starts
                    if self._continuing:  # the command stands still there now
                        self._stand_still()
                return
            continued = self._motion if self._continuing else None
            for m in self.modules:
                m.continued = continued
                m.begin(st)
            self.phase = phase = Phase.RUN
            self.t_started_s = t_s
            if self.preconditions:
                self.queue.push(t_s, self.builtin_ids["pre"])
        if phase not in RUNNING:
            return
        if t_s - self.t_started_s >= self.timeout_s:
            why = f"{self.name} ran {self.timeout_s:g} s (its timeout_s) without ending"
            self.raise_t3(t_s, TASK_TIMEOUT, why)
            self.fault_reason = f"{TASK_TIMEOUT}: {why}"
            return
        self.ticks += 1
        if self.decimation > 1 and (self.ticks - 1) % self.decimation:
            if self._holding_previous:
                self._out = self.sent
            return
        self.run_law(t_s)
        if self.phase is FAULT:
            return
        cmd = self.command
        if self._holding_previous:
            self._holding_previous = False
            if self._blend_ticks:
                if self._continuing:  # from where the outgoing command goes on to
                    extrapolate(self._motion, self._robot_period_s, self._offset)
                    self._offset -= cmd
                else:
                    np.subtract(self.sent, cmd, out=self._offset)
                if self._blend_step_rad:  # long enough that no step outruns the joints (a switch)
                    need = max(
                        abs(o) / s for o, s in zip(self._offset.tolist(), self._blend_step_rad, strict=True)
                    )
                    self._blend_ticks = self._blend_left = max(self._blend_ticks, math.ceil(need))
        if self._blend_left:
            np.multiply(self._offset, self._blend_left / self._blend_ticks, out=self._blended)
            np.add(self._blended, cmd, out=self._blended)
            cmd = self._blended
            self._blend_left -= 1
        self._out = cmd

    def _stand_still(self) -> None:
        m = self._motion
        m.q_rad[:] = self.sent
        m.dq_rad_s[:] = 0.0
        m.ddq_rad_s2[:] = 0.0

    def _send(self, t_s: float, cmd: npt.NDArray[np.float64]) -> None:
        flags = self.resource.write(t_s, cmd)
        if cmd is self.command:
            self._sent_view[:] = self._command_view
        elif cmd is not self.sent:  # blended
            self.sent[:] = cmd
        if self._history is not None:
            self._history.record(cmd)
        self.wrote = True
        self.last_write_flags = flags
        if flags & T3_MASK:
            self._resource_t3(t_s, flags)

    def _preconditions_hold(self, t_s: float) -> bool:
        ok = True
        for p in self.preconditions:
            if not p.holds():
                ok = False
                if t_s - self.t_started_s >= p.timeout_s:
                    self.phase = Phase.PRE_FAILED
                    self.fault_reason = f"precondition {p.name} not met within {p.timeout_s:g} s"
                    self.queue.push(t_s, self.builtin_ids["PreconditionTimeout"])
                    return False
        return ok

    def emit_event(self, t_s: float, ev: ShellEvent) -> None:
        """A shell event rose in this tick (tick-safe)."""
        self.queue.push(t_s, ev.event_id)
        kind = ev.kind
        if kind is EventKind.T1:
            self._apply(ev.reaction)
        elif kind is EventKind.POST:
            if self.phase is Phase.RUN:
                self.phase = Phase.DONE
        elif kind is EventKind.T2:
            if self.phase is Phase.RUN:
                self.phase = Phase.ABORTED
        elif kind is EventKind.T3:
            self.resource.safe_stop()
            self.phase = Phase.FAULT
            self.fault_reason = ev.name
            self.fault = self._fault_for(ev.name, "")

    def _resource_t3(self, t_s: float, flags: int) -> None:
        self.reported_t3 |= flags & T3_MASK
        if flags & Status.FAULT:
            name = "ResourceFault"
        elif flags & Status.COMM_LOST:
            name = "CommLost"
        else:
            name = "LimitViolation"
        self.raise_t3(t_s, name)

    @staticmethod
    def _apply(changes: Sequence[tuple[Module, Parameter, npt.NDArray[np.float64]]]) -> None:
        for module, param, arr in changes:
            param.value[...] = arr
            module.on_parameter_change(param.name)
