"""Loop supervision in the automaton thread: type 3 faults, aborts, resets, the command
daemon's link.

A type 3 exception has already safe-stopped the resource from the control thread; here it is
recorded (`fault`, in words) so that nothing starts until `reset`. A reset is a sequence over
several control ticks (the device leaves its fault, then the stop is cleared) and talks to the
device (a servo's reboot, a controller's unlock or reconnection: up to seconds): that part runs
in a thread of its own, and the automaton thread answers with a `Pending` reply that it polls.
Whatever ends that thread is the reset's answer: an error of any kind (a device's OSError, a
bug) is a refusal in words naming the resource, never a success; a thread that hangs is named
with the step it is in and the line it waits at, in the reply and in every later refusal.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable
from logging import WARNING
from typing import Protocol, cast

from orccadd.config.robot import RobotConfig
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.ports import LoopPort, ResourcePort
from orccadd.daemon.procedure import MissionControl
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.errors import OrccaddError
from orccadd.fault import Fault, FaultKind, StopCause
from orccadd.physres.base import PhysicalResource
from orccadd.runtime.threads import ThreadGroup, line_of
from orccadd.types import Status
from orccadd.wire.commands import RESET_REPLY_S

log = logging.getLogger("orccadd.machine")

FAULTS_KEPT = 32  # the last stop causes `describe` lists, for the logs' fault records
RESET_WAIT_S = 2.0  # longest wait for a device to leave its fault after a reset (bus round trips)
RESET_DEVICE_S = 30.0  # longest a device's reset may take (a controller reconnected, a servo rebooted)
assert RESET_DEVICE_S + RESET_WAIT_S < RESET_REPLY_S  # its refusal comes before the clients give up


class FaultHistory:
    """The stop causes of every resource, numbered in one sequence (the trace's fault records
    name them by number): a new fault is a new number, even with the same words."""

    def __init__(self) -> None:
        self.count = 0
        self.history: deque[tuple[int, StopCause]] = deque(maxlen=FAULTS_KEPT)  # (number, cause)
        self.on_cause: Callable[[int], None] = lambda n: None  # a new cause recorded, its number

    def record(self, cause: StopCause) -> None:
        self.count += 1
        self.history.append((self.count, cause))
        self.on_cause(self.count)

    def recent(self) -> list[dict[str, object]]:
        """The last causes, numbered."""
        return [{"n": n, **c.to_wire()} for n, c in self.history]


class ControlThread(Protocol):
    """The resource's unit as its reset uses it (`orccadd.daemon.unit.ResourceUnit`): its threads
    (a reset's device work runs in them) and its control thread, started again if it failed."""

    threads: ThreadGroup
    stalled: str  # why its control thread counts as hung ("": it does not)

    def control_ended(self) -> bool: ...
    def still_stalled(self) -> str: ...
    def device_reset(self, wait_s: float) -> DeviceReset: ...


class DeviceReset(Protocol):
    """A reset's device work under way (`_DeviceReset` here, or a unit process's)."""

    def running(self) -> bool: ...
    def where(self) -> str: ...
    def done(self) -> bool: ...


class Supervisor:
    """One resource's: its safe stop's cause, its reset."""

    def __init__(
        self,
        cfg: RobotConfig,
        resource: ResourcePort,
        loop: LoopPort,
        mission: MissionControl,
        note: Callable[..., None],
        history: FaultHistory | None = None,
    ) -> None:
        self.cfg = cfg
        self.resource = resource
        self.loop = loop
        self.mission = mission
        self.note = note
        self.fault: StopCause | None = None  # why the resource was safe-stopped (None when not)
        self.history = history if history is not None else FaultHistory()
        self._resetting: DeviceReset | None = None  # the device's last reset
        self.unit: ControlThread | None = None  # its unit (`ResourceUnit.bind`); None: a test's
        self.threads = ThreadGroup("supervisor")  # a reset's device work when there is no unit

    def on_t3(self, event: str, fault: Fault | None) -> None:
        """The type 3 exception `event` safe-stopped the arm, about `fault` (the task's)."""
        if self.fault is None:
            if fault is None:
                fault = Fault(FaultKind.DEVICE, self.resource.name, "safe stop (no message)")
            self._record(StopCause(event, fault))
            self.note(f"type 3: {event}: safe stop ({fault})", WARNING)

    def stop(self, why: str, kind: FaultKind = FaultKind.ABORT) -> None:
        """Safe stop at the resource's next tick, remembering why (an abort: the machine's, which
        ends the run)."""
        self.loop.request_safe_stop()
        if self.fault is None:
            self._record(StopCause("", Fault(kind, self.resource.name, why)))

    def _record(self, cause: StopCause) -> None:
        self.fault = cause
        self.history.record(cause)

    def begin_reset(self, on_done: Callable[[], None]) -> Result | Pending:
        """Clear a safe stop once the arm is at rest: the device's fault first (if it has one),
        then the stop. Refused (CommandError) while a run or the stop is still under way.

        The device's reset talks to it (a servo's reboot, a controller's unlock, a reconnection:
        up to seconds): it runs in a thread of its own, and the automaton thread only polls."""
        res = self.resource
        if not (self.fault or res.stopping_or_stopped):
            return {"reset": False, "detail": "nothing to reset"}
        self.check_reset()
        wait_s = max(100 * self.cfg.control_period_s, RESET_WAIT_S)
        unit = self.unit
        if unit is not None:
            device = self._resetting = unit.device_reset(wait_s)
        else:
            # a supervisor without a unit: a test's, given the resource and its loop themselves
            device = self._resetting = _DeviceReset(
                self.threads, cast(PhysicalResource, res), cast(SwitchingLoop, self.loop), wait_s
            )

        def poll() -> Result | None:
            if not device.done():
                return None
            self.fault = None
            if unit is not None:
                unit.stalled = ""  # it ticks again: a new hang is a new fault
            self.note(f"reset: {res.name}: stop cleared, holding")
            on_done()
            return {"reset": True}

        def expire() -> Result:
            why = (
                f"the reset of {res.name} did not end within {RESET_DEVICE_S + wait_s:g} s (still running "
                f"{device.where()}): a new reset is refused until it ends (if it never does: restart orccadd)"
            )
            self.note(why, WARNING)
            raise CommandError(why)

        return Pending(poll, time.monotonic_ns() + int((RESET_DEVICE_S + wait_s) * 1e9), expire)

    def check_reset(self) -> None:
        """`CommandError` if a reset cannot begin now (a run or the stop still under way)."""
        if self.mission.running:
            raise CommandError(self._still_running())
        hung = self.unit.still_stalled() if self.unit is not None else ""
        if hung:
            raise CommandError(
                f"{self.resource.name}: {hung}: a reset waits until the call returns "
                "(if it never does: restart orccadd)"
            )
        ended = self.unit is not None and self.unit.control_ended()
        if not ended and not self.resource.state.status & Status.STOPPED:
            raise CommandError(
                f"the safe stop of {self.resource.name} is still under way: wait until it is at rest"
            )
        if self._resetting is not None and self._resetting.running():
            raise CommandError(
                f"a reset of {self.resource.name} is already under way ({self._resetting.where()}): "
                "a new one is refused until it ends (if it never does: restart orccadd)"
            )

    def _still_running(self) -> str:
        """Why a reset waits for the mission, and what ends it: the operator inputs it may be
        waiting for (a safe procedure that awaits an acknowledgement), `stop`, `abort`."""
        loaded = self.mission.mission
        ops = loaded.describe()["operator_inputs"] if loaded is not None else []
        inputs = [str(i) for i in ops] if isinstance(ops, list) else []
        send = " or ".join(f"`orccadctl send {i}`" for i in inputs)
        ends = f"give it the input it waits for ({send}) or end it with" if send else "end it with"
        return (
            f"the mission is still running (its safe procedure, after the stop of {self.resource.name}): "
            f"{ends} `orccadctl stop` (or `abort`), then reset"
        )


class _DeviceReset:
    """The reset's talk with the device, in a thread of its own: the control thread started
    again if it had failed (`restart`: it ticks the resource, safe-stopped), the device's fault reset (if it
    has one), a wait (up to `wait_s`) for its reads to show neither fault nor lost link, the Hold
    task restarted from the measured state while the stop still holds (the outgoing task's last
    command is stale: the arm may be elsewhere now, after a controller's restart), then the
    stop cleared. `done()` re-raises its error as a CommandError: whatever the thread raised (an
    OrccaddError's words; any other exception by type and words, naming the resource and the
    step), so that a reset whose device work failed never answers success."""

    def __init__(
        self,
        threads: ThreadGroup,
        resource: PhysicalResource,
        loop: SwitchingLoop,
        wait_s: float,
        restart: Callable[[], None] | None = None,
    ) -> None:
        self._error = ""
        self._started = time.monotonic()
        self.step = "starting"  # what the thread does now, in words (`where`)
        self._thread = threads.start(self._run, resource, loop, wait_s, restart, name="device-reset")

    def _run(
        self, res: PhysicalResource, loop: SwitchingLoop, wait_s: float, restart: Callable[[], None] | None
    ) -> None:
        try:
            if restart is not None:
                self.step = "starting the control thread again (restart_control)"
                restart()
            res.clear_output_fault()  # an output action that failed: the reset's to forget
            if res.description.fault_reset:
                self.step = "the device's fault reset (reset_fault)"
                res.reset_fault()
            self.step = "the wait for reads without a fault"
            end = time.monotonic() + wait_s
            while res.state.status & (Status.FAULT | Status.COMM_LOST):  # the ticks' reads
                if time.monotonic() > end:
                    self._error = f"the device still reports a fault after the reset ({res.fault_message})"
                    return
                time.sleep(0.01)
            self.step = "the wait for the control loop to take the Hold task"
            request = loop.request_switch(loop.hold, fresh=True)
            while not loop.switched(request):
                if time.monotonic() > end:
                    self._error = "the control loop did not take the Hold task"
                    return
                time.sleep(0.002)
            self.step = "clearing the stop (clear_stop)"
            res.clear_stop()
        except OrccaddError as e:
            self._error = str(e)
        except Exception as e:  # a device's OSError, a bug: a refusal that says so, never a success
            log.error("reset of %s: %s failed", res.name, self.step, exc_info=True)
            self._error = f"the reset of {res.name} failed in {self.step}: {type(e).__name__}: {e}"
        finally:
            self.step = "ended"

    def running(self) -> bool:
        return self._thread.is_alive()

    def where(self) -> str:
        """For how long it runs, its step, and the line it is at outside the standard library
        (the words for a reset that hangs: `for 41 s, in ..., at orccadd/x.py:123 (read_cycle)`)."""
        line = line_of(self._thread)
        at = f", at {line}" if line else ""
        return f"for {time.monotonic() - self._started:.0f} s, in {self.step}{at}"

    def done(self) -> bool:
        if self._thread.is_alive():
            return False
        if self._error:
            raise CommandError(self._error)
        return True
