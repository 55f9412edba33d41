"""Algorithmic modules and their registry (`MODULES`, `register`, entry points `orccadd.modules`)."""

from importlib.metadata import entry_points

from orccadd.modules import (  # noqa: F401 - register built-ins
    cartesian,
    cartesian_watchers,
    control,
    filters,
    follow,
    force,
    hold,
    kinematic_control,
    operational_space,
    trajectory,
    ur,
    visual,
    watchers,
)
from orccadd.modules.base import MODULES, CommandMotion, Module, ModuleContext, Parameter, Port, register


def module_class(type_name: str) -> type[Module] | None:
    """The module class registered as `type_name` (built-in or entry point), or None."""
    if type_name in MODULES:
        return MODULES[type_name]
    for ep in entry_points(group="orccadd.modules"):
        if ep.name == type_name:
            cls = ep.load()
            MODULES[type_name] = cls
            return cls  # type: ignore[no-any-return]
    return None


__all__ = [
    "MODULES",
    "CommandMotion",
    "Module",
    "ModuleContext",
    "Parameter",
    "Port",
    "module_class",
    "register",
]
