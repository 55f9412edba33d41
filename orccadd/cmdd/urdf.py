"""Where the robot's URDF is, for the logs' MCAP files (the command daemon reads the robot config
itself; it may not import the model code)."""

from __future__ import annotations

from pathlib import Path

from orccadd.config.robot import RobotConfig
from orccadd.config.urdf import resolve_urdf
from orccadd.errors import OrccaddError


def urdf_path(cfg: RobotConfig) -> Path | None:
    """The URDF file of `cfg` (None if it cannot be found: the logs then say so)."""
    try:
        return resolve_urdf(cfg)
    except OrccaddError:
        return None
