"""Typed, strict configuration files (robots, tasks): pure data and validation, no backend."""

from orccadd.config.robot import (
    JointConfig,
    LimitsConfig,
    ModelConfig,
    ResourceConfig,
    RobotConfig,
    SafeStopConfig,
    read_robot_config,
    read_toml,
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
    "read_robot_config",
    "read_toml",
]
