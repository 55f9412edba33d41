"""What the real-time process's command handlers use of the execution machine and its units
(`orccadd.daemon.machine`), as protocols: the handlers' modules need not import the machine."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from orccadd.config.robot import RobotConfig
from orccadd.config.station import StationConfig
from orccadd.daemon.ports import LoopPort, OutputsPort, QueuePort, ResourcePort
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.publisher import Publisher
from orccadd.daemon.supervision import Supervisor
from orccadd.physres.base import PhysicalResource
from orccadd.task import RobotTask
from orccadd.task.events import EventQueue, EventRegistry
from orccadd.task.task import ParameterChange


class UnitView(Protocol):
    """What the handlers use of one resource's unit (`orccadd.daemon.unit.ResourceUnit`)."""

    cfg: RobotConfig
    supervisor: Supervisor

    @property
    def name(self) -> str: ...
    @property
    def resource(self) -> ResourcePort: ...
    @property
    def task_resource(self) -> PhysicalResource: ...
    @property
    def queue(self) -> QueuePort: ...
    @property
    def task_queue(self) -> EventQueue: ...
    @property
    def loop(self) -> LoopPort: ...
    @property
    def outputs(self) -> OutputsPort: ...
    def load_mission(self, message: dict[str, Any]) -> None: ...
    def post_tune(self, task: RobotTask, path: str, value: Any, change: ParameterChange) -> int: ...
    def tune_acked(self, seq: int) -> int | None: ...


class Machine(Protocol):
    """What the handlers use of the execution machine (`orccadd.daemon.machine.Machine`)."""

    station: StationConfig
    registry: EventRegistry
    pub: Publisher
    mission: MissionControl
    allow_fault_injection: bool

    @property
    def units(self) -> Sequence[UnitView]: ...
    @property
    def default(self) -> UnitView: ...
    def unit(self, name: str) -> UnitView: ...
    def unit_of(self, task: RobotTask) -> UnitView: ...
    def abort(self, why: str) -> None: ...
    def now_s(self) -> float: ...
    def note(self, msg: str) -> None: ...
    def describe(self) -> dict[str, Any]: ...
