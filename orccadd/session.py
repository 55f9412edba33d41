"""A robot session: config → resource → tasks → control loop, for programs that run
Robot-Tasks by hand (the demo, tests, benchmarks). The daemon builds on the same pieces.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from orccadd.config.robot import RobotConfig
from orccadd.physres import PhysicalResource
from orccadd.robot import create_resource, load_robot_config
from orccadd.runtime.clock import Clock
from orccadd.task import EventQueue, EventRegistry, RobotTask, build_task, load_task_file
from orccadd.task.loop import ControlLoop
from orccadd.types import CommandMode


@dataclass
class Session:
    """One robot: its resource (configured and active), an event registry and queue."""

    config: RobotConfig
    resource: PhysicalResource
    registry: EventRegistry = field(default_factory=EventRegistry)
    queue: EventQueue = field(default_factory=EventQueue)

    @staticmethod
    def open(robot_config: str | Path, mode: CommandMode = CommandMode.TORQUE) -> Session:
        """Load the config, build, configure and activate the resource. Not for a tick."""
        return Session.from_config(load_robot_config(robot_config), mode)

    @staticmethod
    def from_config(cfg: RobotConfig, mode: CommandMode = CommandMode.TORQUE) -> Session:
        res = create_resource(cfg)
        res.configure()
        res.activate(mode)
        return Session(cfg, res)

    def task(self, task_file: str | Path) -> RobotTask:
        return build_task(load_task_file(task_file), self.resource, self.registry, self.queue)

    def loop(self, clock: Clock, *, overrun_limit: int = 3) -> ControlLoop:
        return ControlLoop(self.resource, clock, overrun_limit=overrun_limit)

    def event_names(self) -> list[str]:
        """Drain the queue and name the events (not for a tick)."""
        return [self.registry.info(eid).name for _, eid in self.queue.drain()]

    def close(self) -> None:
        self.resource.shutdown()
