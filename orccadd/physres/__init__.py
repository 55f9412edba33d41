"""Physical Resources: backends registered by name, imported only when chosen.

Built-in backends are listed in `BACKENDS`; third-party ones register under the
`orccadd.physres` entry-point group. `orccadd.robot` builds a resource from a config.
"""

from __future__ import annotations

import importlib
import importlib.util
from importlib.metadata import entry_points

from orccadd.errors import ConfigError
from orccadd.physres.base import PhysicalResource
from orccadd.state import JointState
from orccadd.types import T3_MASK, CommandMode, Lifecycle, Status

BACKENDS: dict[str, tuple[str, str]] = {
    "sim": ("orccadd.physres.sim", "SimulatedArm"),
    "sim_process": ("orccadd.physres.sim_process", "SimProcessArm"),
    "canopen402": ("orccadd.physres.canopen402", "Canopen402Arm"),
    "ur_rtde": ("orccadd.physres.ur_rtde", "UrRtdeArm"),
    "dynamixel": ("orccadd.physres.dynamixel", "DynamixelArm"),
    "ethercat402": ("orccadd.physres.ethercat402", "Ethercat402Arm"),
}

# the bus packages a built-in backend needs, and the extra that installs them
EXTRAS: dict[str, tuple[str, tuple[str, ...]]] = {
    "canopen402": ("canopen", ("can", "canopen")),
    "dynamixel": ("dynamixel", ("serial", "dynamixel_sdk")),
    "ur_rtde": ("ur", ("rtde_control", "rtde_receive", "dashboard_client")),
    "ethercat402": ("ethercat", ("pysoem",)),
}


def _check_extra(name: str, file: str) -> None:
    if name not in EXTRAS:
        return
    extra, modules = EXTRAS[name]
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        raise ConfigError(
            file,
            "resource.backend",
            f"(={name!r}) needs the Python package(s) {', '.join(missing)}, not installed: "
            f"pip install 'orccadd[{extra}]'",
        )


def backend_names() -> list[str]:
    names = set(BACKENDS)
    names.update(ep.name for ep in entry_points(group="orccadd.physres"))
    return sorted(names)


def backend_class(name: str, file: str = "") -> type[PhysicalResource]:
    """The resource class for backend `name`; a ConfigError naming the choices otherwise."""
    if name in BACKENDS:
        _check_extra(name, file)
        module, attr = BACKENDS[name]
        cls = getattr(importlib.import_module(module), attr)
    else:
        eps = [ep for ep in entry_points(group="orccadd.physres") if ep.name == name]
        if not eps:
            raise ConfigError(
                file, "resource.backend", f"(={name!r}) must be one of {', '.join(backend_names())}"
            )
        cls = eps[0].load()
    if not (isinstance(cls, type) and issubclass(cls, PhysicalResource)):
        raise ConfigError(file, "resource.backend", f"(={name!r}) does not name a PhysicalResource")
    return cls


__all__ = [
    "BACKENDS",
    "T3_MASK",
    "CommandMode",
    "JointState",
    "Lifecycle",
    "PhysicalResource",
    "Status",
    "backend_class",
    "backend_names",
]
