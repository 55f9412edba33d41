"""Robot-Tasks: declared in files, built into a flat schedule inside a reactive shell."""

from orccadd.task.builder import build_task
from orccadd.task.events import (
    EventInfo,
    EventKind,
    EventQueue,
    EventRegistry,
    event_name,
)
from orccadd.task.spec import TaskSpec, load_task_file, parse_task
from orccadd.task.task import RobotTask, TaskSignature
from orccadd.types import BUILTIN_T3, Phase

__all__ = [
    "BUILTIN_T3",
    "EventInfo",
    "EventKind",
    "EventQueue",
    "EventRegistry",
    "Phase",
    "RobotTask",
    "TaskSignature",
    "TaskSpec",
    "build_task",
    "event_name",
    "load_task_file",
    "parse_task",
]
