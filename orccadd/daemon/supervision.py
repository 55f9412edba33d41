"""Loop supervision in the automaton thread: type 3 faults, aborts, resets, the command
daemon's link.

A type 3 exception has already safe-stopped the resource from the control thread; here it is
recorded (`fault`, in words) so that nothing starts until `reset`. A reset is a sequence over
several control ticks (the device leaves its fault, then the stop is cleared): it returns a
`Pending` reply instead of sleeping in the automaton thread.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from orccadd.config.robot import RobotConfig
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.errors import OrccaddError
from orccadd.physres.base import PhysicalResource
from orccadd.types import Status
from orccadd.wire.schema import MissionResult

RESET_WAIT_S = 2.0  # longest wait for a device to leave its fault after a reset (bus round trips)


class Supervisor:
    def __init__(
        self,
        cfg: RobotConfig,
        resource: PhysicalResource,
        loop: SwitchingLoop,
        mission: MissionControl,
        note: Callable[[str], None],
    ) -> None:
        self.cfg = cfg
        self.resource = resource
        self.loop = loop
        self.mission = mission
        self.note = note
        self.fault = ""  # why the resource was safe-stopped ("" when not)

    def on_t3(self, name: str) -> None:
        if not self.fault:
            self.fault = f"{name} ({self.resource.fault_message or 'safe stop'})"
            self.note(f"type 3: {name}: safe stop")

    def abort(self, why: str) -> None:
        """Safe stop at the next tick, remember why, end the run (`aborted`)."""
        self.loop.request_safe_stop()
        self.fault = self.fault or why
        self.note(f"abort: {why}")
        self.mission.end(MissionResult.ABORTED)

    def link_lost(self, why: str) -> None:
        self.note(why)
        if self.cfg.daemon.on_command_daemon_loss == "safe_stop" and self.mission.running:
            self.abort(f"{why} (on_command_daemon_loss = safe_stop)")

    def begin_reset(self, on_done: Callable[[], None]) -> Result | Pending:
        """Clear a safe stop once the arm is at rest: the device's fault first (if it has one),
        then the stop. Refused (CommandError) while a run or the stop is still under way."""
        res = self.resource
        if not (self.fault or res.stopping_or_stopped):
            return {"reset": False, "detail": "nothing to reset"}
        if self.mission.running:
            raise CommandError("the mission is still running (its safe procedure): stop or abort it first")
        if not res.state.status & Status.STOPPED:
            raise CommandError("the safe stop is still under way: wait until the arm is at rest")
        if res.description.fault_reset:
            try:
                res.reset_fault()
            except OrccaddError as e:
                raise CommandError(str(e)) from None

        def finish() -> Result:
            try:
                res.clear_stop()
            except OrccaddError as e:
                raise CommandError(str(e)) from None
            self.fault = ""
            self.loop.request_switch(self.loop.hold)
            self.note("reset: stop cleared, holding")
            on_done()
            return {"reset": True}

        def poll() -> Result | None:
            return None if res.state.status & (Status.FAULT | Status.COMM_LOST) else finish()

        done = poll()
        if done is not None:
            return done
        wait_s = max(100 * self.cfg.control_period_s, RESET_WAIT_S)
        return Pending(poll, time.monotonic_ns() + int(wait_s * 1e9), finish)
