"""Typed, strict configuration files (robots, tasks)."""

from orccadd.config.robot import (
    JointConfig,
    LimitsConfig,
    ModelConfig,
    ResourceConfig,
    RobotConfig,
    SafeStopConfig,
    load_robot_config,
    read_toml,
    with_backend,
)
from orccadd.config.schema import field, load_dataclass

__all__ = [
    "JointConfig",
    "LimitsConfig",
    "ModelConfig",
    "ResourceConfig",
    "RobotConfig",
    "SafeStopConfig",
    "field",
    "load_dataclass",
    "load_robot_config",
    "read_toml",
    "with_backend",
]
