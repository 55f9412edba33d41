"""Algorithmic modules: one block of a control law, with declared ports and parameters.

Writing a module: subclass `Module`, declare ports and parameters in `__init__`, fill outputs
in place in `update`, and `@register("type_name")` it (or publish it under the `orccadd.modules`
entry-point group). The worked example is `orccadd/modules/filters.py` (`low_pass`), explained
in docs/writing-a-module.md.

Ports carry a shape, a unit and a dtype; an output owns a preallocated numpy buffer and wiring
makes the input's `value` *be* that buffer, so a tick copies and allocates nothing. Parameters
carry a default, bounds, a unit and whether they are tunable at run time; a tuned value is
checked when it is asked for and applied in place at a tick boundary.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from orccadd.errors import ParameterError
from orccadd.model import RobotModel
from orccadd.state import JointState

FloatArray = npt.NDArray[np.float64]
# (t_s, one value per input) -> one value per output; a vector is a list of floats, a scalar a
# bool or a float (see `Module.kernel`)
Kernel = Callable[..., tuple[Any, ...]]


@dataclass(frozen=True)
class ModuleContext:
    """What a module may know of its surroundings (fixed for the task's life)."""

    task: str
    model: RobotModel
    period_s: float

    @property
    def dof(self) -> int:
        return self.model.dof


class CommandMotion:
    """The position command a task continues at a switch (`Module.continued`): the outgoing
    task's last command `q_rad` and its velocity and acceleration then, by finite differences of
    the commands before it (rad, rad/s, rad/s^2). Preallocated by its owner, written in place."""

    __slots__ = ("ddq_rad_s2", "dq_rad_s", "q_rad")

    def __init__(self, dof: int) -> None:
        self.q_rad: FloatArray = np.zeros(dof)
        self.dq_rad_s: FloatArray = np.zeros(dof)
        self.ddq_rad_s2: FloatArray = np.zeros(dof)


class Port:
    """An input or output port. `value` is the numpy buffer (shared through wiring)."""

    __slots__ = ("dtype", "is_input", "module", "name", "shape", "unit", "value")

    def __init__(
        self, module: str, name: str, shape: tuple[int, ...], unit: str, dtype: type, is_input: bool
    ) -> None:
        self.module = module
        self.name = name
        self.shape = shape
        self.unit = unit
        self.dtype = np.dtype(dtype)
        self.is_input = is_input
        self.value: npt.NDArray[Any] = np.zeros(shape, dtype=dtype)

    @property
    def path(self) -> str:
        return f"{self.module}.{self.name}"

    def describe(self) -> str:
        kind = "bool" if self.dtype == np.bool_ else f"{self.shape}"
        return f"{self.path} [{kind}, {self.unit or '-'}]"


class Parameter:
    """A declared parameter. `value` is a numpy array updated in place (never rebound)."""

    __slots__ = (
        "bounds", "default", "element", "given", "integer", "module", "name", "per_joint", "required",
        "shape", "tunable", "unit", "value",
    )  # fmt: skip

    def __init__(
        self,
        module: str,
        name: str,
        default: Any,
        bounds: tuple[Any, Any],
        unit: str,
        tunable: bool,
        shape: tuple[int, ...],
        integer: bool = False,
        required: bool = False,
        per_joint: bool = False,
        element: str = "joint",
    ) -> None:
        self.module = module
        self.name = name
        self.bounds = bounds
        self.unit = unit
        self.tunable = tunable
        self.shape = shape
        self.integer = integer  # whole numbers only (a count of ticks): 2.5 is refused, not truncated
        # one value per joint that one number must not give every joint (a position: `tune
        # Reach.traj.target_rad 0.1` would send all six there); gains take one number for all
        self.per_joint = per_joint
        self.element = element  # what each of a per_joint vector's numbers is for (its errors say)
        self.value: FloatArray = np.zeros(shape)
        self.value[...] = self.check(default)
        self.default = self.value.copy()
        # a mission's task must set it (task file or `set` line): the default is a placeholder
        self.required = required
        self.given = False

    @property
    def path(self) -> str:
        return f"{self.module}.{self.name}"

    def check(self, value: Any) -> FloatArray:
        """The value as an array of this parameter's shape, or ParameterError saying why."""
        if not _numbers(value):  # numpy would take True as 1 and "3" as 3.0
            raise self._error(f"(={value!r}) must be a number or a list of numbers")
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != self.shape:
            if arr.shape == () and self.shape != () and self.per_joint:
                n = self.shape[0]
                why = f"one number would send every {self.element} to it"
                raise self._error(f"(={value!r}) must be {n} numbers, one per {self.element}: {why}")
            if arr.shape == () and self.shape != ():
                arr = np.full(self.shape, float(arr))
            else:
                want = "a number" if self.shape == () else f"{self.shape[0]} numbers (or one)"
                raise self._error(f"(={value!r}) must be {want}")
        if self.integer and not (np.isfinite(arr).all() and (arr == np.round(arr)).all()):
            raise self._error(f"(={value!r}) must be a whole number")
        lo, hi = self.bounds
        bad = ~((arr >= lo) & (arr <= hi))
        if bad.any():
            shown = value if np.ndim(value) == 0 else arr.tolist()
            i = int(np.flatnonzero(bad)[0]) if bad.ndim else 0
            lo_i = float(np.broadcast_to(lo, bad.shape)[i] if bad.ndim else lo)
            hi_i = float(np.broadcast_to(hi, bad.shape)[i] if bad.ndim else hi)
            where = f" at index {i}" if np.ndim(value) else ""
            unit = "" if self.unit in ("", "1") else f" {self.unit}"  # a ratio's "1" says nothing
            raise self._error(f"(={shown!r}) must be in [{lo_i:g}, {hi_i:g}]{unit}{where}")
        return arr

    def _error(self, detail: str) -> ParameterError:
        return ParameterError(f"{self.path} {detail}", name=self.name, detail=detail)

    def describe(self) -> dict[str, Any]:
        return {
            "name": self.path,
            "value": self.value.tolist(),
            "bounds": [np.asarray(b).tolist() for b in self.bounds],
            "unit": self.unit,
            "tunable": self.tunable,
            "required": self.required,
        }


def _numbers(value: Any) -> bool:
    """A number, or a flat list/tuple/array of numbers (booleans and strings are not numbers)."""
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "iuf"
    items = value if isinstance(value, list | tuple) else (value,)
    return all(
        isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) for v in items
    )


class Module(ABC):
    """Base of every algorithmic module. Subclasses declare ports/parameters in `__init__`."""

    type_name: ClassVar[str] = ""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        self.name = name
        self.ctx = ctx
        self.inputs: dict[str, Port] = {}
        self.outputs: dict[str, Port] = {}
        self.parameters: dict[str, Parameter] = {}
        # when the task's law starts (`begin`): the position command it continues, or None (it
        # starts from the measured state alone). Set by the task: a position task switched to
        # while the outgoing one commanded, in the tick after; read in `start`
        self.continued: CommandMotion | None = None

    # ---- declarations (constructor only) --------------------------------------------------
    def add_input(self, name: str, shape: tuple[int, ...], unit: str, dtype: type = np.float64) -> Port:
        port = Port(self.name, name, shape, unit, dtype, is_input=True)
        self.inputs[name] = port
        return port

    def add_output(self, name: str, shape: tuple[int, ...], unit: str, dtype: type = np.float64) -> Port:
        port = Port(self.name, name, shape, unit, dtype, is_input=False)
        self.outputs[name] = port
        return port

    def add_parameter(
        self,
        name: str,
        default: Any,
        *,
        bounds: tuple[Any, Any],
        unit: str = "",
        tunable: bool = False,
        shape: tuple[int, ...] = (),
        integer: bool = False,
        required: bool = False,
        per_joint: bool = False,
        element: str = "joint",
    ) -> Parameter:
        """`required`: a task of a mission must set it (its task file or the mission's `set`);
        `default` is then only what a task built outside a mission (a test, a benchmark) starts
        from. A robot-specific gain or a goal, which no default fits. `per_joint`: a vector that a
        single number must not set for every joint (a position); gains take one number for all;
        `element` names what each number is for in its errors ("axis" for a Cartesian vector)."""
        param = Parameter(
            self.name, name, default, bounds, unit, tunable, shape, integer, required, per_joint, element
        )
        self.parameters[name] = param
        return param

    # ---- behaviour ------------------------------------------------------------------------
    def configure(self, values: dict[str, Any]) -> None:
        """Set parameters from the task file (before the task runs)."""
        for key, v in values.items():
            if key not in self.parameters:
                allowed = ", ".join(sorted(self.parameters)) or "none"
                detail = f"is not a parameter of {self.type_name} (parameters: {allowed})"
                raise ParameterError(f"{self.name}.{key} {detail}", name=key, detail=detail)
            self.parameters[key].value[...] = self.parameters[key].check(v)
            self.parameters[key].given = True
            self.on_parameter_change(key)

    def missing(self) -> list[str]:
        """Required parameters not set yet (see `add_parameter`)."""
        return [p.name for p in self.parameters.values() if p.required and not p.given]

    def set_data(self, data: object) -> None:
        """Give the module data that no fixed-shape parameter holds (a planner's trajectory:
        `orccadd/modules/follow.py`), when its task is built; not for a tick. `ParameterError`
        if it takes none, or not this."""
        raise ParameterError(f"{self.name}: a {self.type_name} module takes no data", name="data")

    def needs_data(self) -> bool:
        """True while the module cannot run without data it has not been given (`set_data`)."""
        return False

    def start(self, state: JointState) -> None:
        """Initialise from the measured state when the task starts (no jump in the command)."""

    def begin(self, state: JointState) -> None:
        """What the task calls when its law starts: `start` (and the base's own resets)."""
        self.start(state)

    @abstractmethod
    def update(self, t_s: float) -> None:
        """One tick: read inputs, write outputs in place. No allocation of buffers, no raise."""

    def on_parameter_change(self, name: str) -> None:
        """Called (at a tick boundary) after parameter `name` took a new value."""

    def kernel(self) -> Kernel | None:
        """The update as a function of plain values, for the compiled tick (orccadd/task/
        compiled.py): called with t_s and one value per input in declaration order (a list of
        floats for a vector, a bool or a float for a scalar), it returns one value per output in
        declaration order, in the same form, and keeps the module's state as `update` does. It
        never changes a list after returning it (it may return the same list again: unchanged).
        A module without one (the default) is called through `update` and its ports."""
        return None


class KernelModule(Module):
    """A module written as a kernel: `update` applies it to the ports, so the interpreted and
    the compiled tick run the same code (bit-identical outputs by construction)."""

    def __init__(self, name: str, ctx: ModuleContext) -> None:
        super().__init__(name, ctx)
        self._k: Kernel | None = None
        self._in_ports: tuple[Port, ...] = ()
        self._out_ports: tuple[Port, ...] = ()
        self._last_outs: tuple[Any, ...] | None = None

    @abstractmethod
    def kernel(self) -> Kernel: ...

    def begin(self, state: JointState) -> None:
        self._last_outs = None  # `start` may have written the ports: every output written again
        self.start(state)

    def update(self, t_s: float) -> None:
        k = self._k
        if k is None:  # the ports are all declared by now
            k = self._k = self.kernel()
            self._in_ports, self._out_ports = tuple(self.inputs.values()), tuple(self.outputs.values())
        outs = k(t_s, *[p.value.tolist() for p in self._in_ports])
        last, self._last_outs = self._last_outs, outs
        for i, port in enumerate(self._out_ports):
            value = outs[i]
            # a list returned again is in the port already (scalars are always written: `start`
            # may have reset the port meanwhile)
            if last is None or value is not last[i] or not isinstance(value, list):
                port.value[...] = value


MODULES: dict[str, type[Module]] = {}


def register(type_name: str) -> Any:
    """Class decorator: make a module type available to task files under `type_name`."""

    def deco(cls: type[Module]) -> type[Module]:
        if type_name in MODULES and MODULES[type_name] is not cls:
            raise ValueError(f"module type {type_name!r} registered twice")
        cls.type_name = type_name
        MODULES[type_name] = cls
        return cls

    return deco
