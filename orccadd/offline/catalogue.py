"""`orccadctl modules`: the module catalogue — each type, its ports (units, shapes) and its
parameters (defaults, bounds, units, tunable or not), as a robot config sizes them."""

from __future__ import annotations

from importlib.metadata import entry_points

import numpy as np

from orccadd.config.shipped import robot_config_path
from orccadd.model import RobotModel
from orccadd.modules import MODULES, Module, ModuleContext, Parameter, Port, module_class
from orccadd.robot import load_robot_config


def _shape(shape: tuple[int, ...], dtype: np.dtype) -> str:
    if dtype == np.bool_:
        return "bool"
    return "scalar" if shape == () else "×".join(str(n) for n in shape)


def _port(p: Port) -> str:
    return f"    {'in ' if p.is_input else 'out'} {p.name:16s} {_shape(p.shape, p.dtype):8s} {p.unit or '-'}"


def _value(v: object) -> str:
    arr = np.asarray(v, dtype=np.float64)
    flat = np.unique(arr)
    return f"{flat[0]:g}" if flat.size == 1 else "[" + ", ".join(f"{x:g}" for x in arr.ravel()) + "]"


def _param(p: Parameter) -> str:
    lo, hi = p.bounds
    tune = "tunable" if p.tunable else "fixed at load"
    default = "required" if p.required else _value(p.default)
    return (
        f"    {p.name:20s} default {default:14s} in [{_value(lo)}, {_value(hi)}] {p.unit or '-'}"
        f"  ({'×'.join(map(str, p.shape)) or 'scalar'}, {tune})"
    )


def describe_module(type_name: str, cls: type[Module], ctx: ModuleContext) -> str:
    m = cls(type_name, ctx)
    doc = (cls.__doc__ or "").strip().splitlines()
    lines = [f"{type_name}: {doc[0] if doc else ''}"]
    lines += [_port(p) for p in (*m.inputs.values(), *m.outputs.values())]
    lines += [_param(p) for p in m.parameters.values()] or ["    (no parameters)"]
    return "\n".join(lines)


def catalogue(robot: str) -> str:
    """Every registered module type (built-in and entry points), sized for `robot`."""
    cfg = load_robot_config(robot_config_path(robot))
    ctx = ModuleContext(task="catalogue", model=RobotModel.from_config(cfg), period_s=cfg.control_period_s)
    for ep in entry_points(group="orccadd.modules"):
        module_class(ep.name)
    head = f"modules ({len(MODULES)}), sized for {cfg.name} ({cfg.dof} joints):"
    return "\n\n".join([head, *(describe_module(n, MODULES[n], ctx) for n in sorted(MODULES))])
