"""Where a robot config's URDF is: a path relative to the config, or a file of the
example-robot-data package (`example-robot-data:robots/...`). For the model, and for the command
daemon, which attaches the URDF to its MCAP logs without loading the model."""

from __future__ import annotations

import sys
from pathlib import Path

from orccadd.config.robot import RobotConfig
from orccadd.errors import ConfigError, ModelError

ERD_PREFIX = "example-robot-data:"


def example_robot_data_dir() -> Path:
    """The share folder of the example-robot-data package (installed by pip under cmeel.prefix)."""
    for entry in sys.path:
        candidate = Path(entry) / "cmeel.prefix" / "share" / "example-robot-data"
        if candidate.is_dir():
            return candidate
    raise ModelError("the example-robot-data package is not installed (pip install example-robot-data)")


def resolve_urdf(cfg: RobotConfig) -> Path:
    """The URDF file `cfg` names; `ConfigError` naming the key if there is none."""
    urdf = cfg.model.urdf
    shown = urdf[:200].encode("utf-8", "backslashreplace").decode()
    try:
        path = (
            example_robot_data_dir() / urdf[len(ERD_PREFIX) :]
            if urdf.startswith(ERD_PREFIX)
            else cfg.resolve(urdf)
        )
        found = path.is_file()
    except (OSError, ValueError) as e:  # a NUL, a name too long, ...
        raise ConfigError(cfg.source, "model.urdf", f"(={shown!r}) is not a usable path ({e})") from None
    if not found:
        raise ConfigError(cfg.source, "model.urdf", f"(={shown!r}) names no file ({path})")
    return path
