"""One resource and its clock domain, as one object that owns everything it starts.

A `ResourceUnit` builds what the domain needs from the resource's config — its Hold task, event
queue, control loop (`SwitchingLoop`), output thread (`OutputWorker`) — and runs its threads in
a scope of its own (`threads`, joined on exit, none a daemon thread): the control thread, the
output thread, a reset's device work. Every resource is a unit in the same way; none is special.

Whatever ends the control thread is this resource's fault, never the daemon's end: the thread
safe-stops the resource (`safe_stop()`: the device's own stop, without a tick), records why
(`failure`) and wakes the automaton thread, which records it as the resource's stop cause
(`internal`) and hands it to the mission as that resource's fault (`Machine.on_events`); the
other resources tick on. `reset` starts the control thread again (`restart_control`) before
the device's reset; a thread that fails again at once is the reset's refusal.

A control thread that stops ticking without ending (a device call that never returns: a read
waiting on a silent bus) is found by the automaton thread (`stalled`: no tick for the loop's
watchdog, `watchdog_stale_periods` periods and at least `STALL_MIN_S`): the resource is
safe-stopped from a thread of the unit (the call may hang on that device too), the fault is
that resource's (`comm_lost`, naming the line the thread waits at), and the others tick on. The
device's own watchdog stops the arm meanwhile (a drive's heartbeat consumer, a UR's RTDE
watchdog, a servo's bus watchdog); this is what lets the daemon say so and go on with the rest.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.daemon.loop import SwitchingLoop
from orccadd.daemon.outputs import OutputWorker
from orccadd.daemon.supervision import Supervisor, _DeviceReset
from orccadd.errors import OrccaddError
from orccadd.physres.base import PhysicalResource
from orccadd.runtime.clock import Clock
from orccadd.runtime.rt import RealtimeReport, leave_realtime
from orccadd.runtime.threads import ThreadGroup, line_of
from orccadd.task import EventQueue, EventRegistry, RobotTask, build_task, load_task_file
from orccadd.task.task import ParameterChange
from orccadd.types import Phase
from orccadd.wire.schema import H
from orccadd.wire.telemetry import TelemetryBlock

log = logging.getLogger("orccadd")

QUEUE_LEN = 4096  # the loop's events waiting for the automaton thread
HOLDING_WAIT_S = 5.0  # longest `start_control` waits for the loop's first tick
STALL_MIN_S = 0.25  # a control thread is stalled after no tick for this long at least (a
# loaded machine's real-time throttling holds a FIFO thread up to 50 ms: not a hung device)

EnterRealtime = Callable[[int], RealtimeReport]  # SCHED_FIFO for the calling thread


def heartbeat_fresh(cfg: RobotConfig, tel: TelemetryBlock, now_ns: int) -> bool:
    """The resource's control loop ticked within its watchdog's periods (its telemetry says)."""
    stale_s = cfg.daemon.watchdog_stale_periods * cfg.control_period_s
    return now_ns - int(tel.header[H.HEARTBEAT_NS]) < stale_s * 1e9


def stall_after_s(cfg: RobotConfig) -> float:
    """No tick for this long: the resource's control thread is hung."""
    return max(STALL_MIN_S, cfg.daemon.watchdog_stale_periods * cfg.control_period_s)


def stalled_for_s(cfg: RobotConfig, tel: TelemetryBlock, started_ns: int, now_ns: int) -> float:
    """How long the control loop has not ticked (since its last tick or its start), if it is
    hung by `stall_after_s`; 0.0 if it is not."""
    last_ns = max(int(tel.header[H.HEARTBEAT_NS]), started_ns)
    quiet_s = (now_ns - last_ns) * 1e-9
    return quiet_s if quiet_s >= stall_after_s(cfg) else 0.0


class ControlThreadError(OrccaddError):
    """A unit's control thread ended on an exception (or did not tick in time)."""


def hold_name(station_listed: bool, resource: str) -> str:
    """The name of `resource`'s Hold task: events and tunes name it (`Hold` alone in a daemon of
    one unlisted resource)."""
    return f"Hold_{resource}" if station_listed else "Hold"


def hold_task(
    cfg: RobotConfig, resource: PhysicalResource, registry: EventRegistry, queue: EventQueue, name: str
) -> RobotTask:
    """The resource's own task, which holds it for as long as nothing else commands it."""
    spec = load_task_file(cfg.resolve(cfg.daemon.hold_task))
    spec = replace(spec, task=replace(spec.task, name=name, timeout_s=float("inf")))
    return build_task(spec, resource, registry, queue)


class ResourceUnit:
    """One resource's clock domain: its config, resource, clock, telemetry block, event queue,
    control loop, supervisor (`bind`), output worker, and the threads that run them."""

    def __init__(
        self,
        cfg: RobotConfig,
        resource: PhysicalResource,
        clock: Clock,
        tel: TelemetryBlock,
        registry: EventRegistry,
        wake_fd: int,
        *,
        hold_name: str,
        queue: EventQueue | None = None,
        loop_type: type[SwitchingLoop] = SwitchingLoop,
    ) -> None:
        """`queue`: where the loop's events go (default: a queue of `QUEUE_LEN` in this process);
        `loop_type`: the control loop's class (a unit process's takes its switches from shared
        memory)."""
        self.cfg = cfg
        self.resource = resource
        self.clock = clock
        self.tel = tel
        self.wake_fd = wake_fd
        self.queue = queue if queue is not None else EventQueue(QUEUE_LEN)
        self.loop = loop_type(
            resource,
            clock,
            hold_task(cfg, resource, registry, self.queue, hold_name),
            self.queue,
            tel,
            wake_fd,
            overrun_limit=cfg.daemon.overrun_limit,
            blend_ticks=int(round(cfg.daemon.switch_blend_s / cfg.control_period_s)),
        )
        self.threads = ThreadGroup(f"unit-{resource.name}", daemon=False)
        self.outputs = OutputWorker(resource, self.threads)
        self.supervisor: Supervisor  # `bind`: it needs the mission, built over every unit's loop
        self.failure = ""  # why the control thread ended, in words ("" while it runs or never ran)
        self.failures = 0  # how many times it ended so
        self._failures_taken = 0
        self.stalled = ""  # why the control thread counts as hung, in words ("": it is not)
        self._started_ns = 0  # when the control thread last started
        self._control: threading.Thread | None = None
        self._enter_rt: EnterRealtime | None = None
        self._priority = 0
        self.on_failure: Callable[[str], None] = lambda why: None  # told, from the dying thread

    @property
    def name(self) -> str:
        return self.resource.name

    @property
    def pid(self) -> int:
        """The process the control loop runs in: this one."""
        return os.getpid()

    @property
    def task_resource(self) -> PhysicalResource:
        """What the mission's tasks are built on: the resource itself."""
        return self.resource

    @property
    def task_queue(self) -> EventQueue:
        """Where the mission's tasks push their events: the loop's queue."""
        return self.queue

    def refresh(self) -> None:
        """Nothing: the automaton thread reads this unit's state where the control thread writes
        it (a unit process's proxy reads it from the telemetry block here)."""

    def load_mission(self, message: dict[str, Any]) -> None:
        """Nothing: the mission's tasks were built on this unit's resource (a unit process's
        proxy sends them to the process here)."""

    def post_tune(self, task: RobotTask, path: str, value: Any, change: ParameterChange) -> int:
        """`change` (of `task`'s `path` to `value`, checked) to the loop's tune mailbox; its
        sequence number. `MailboxFullError` if the loop does not take them."""
        return self.loop.tunes.post(change)

    def tune_acked(self, seq: int) -> int | None:
        """The tick that applied tune `seq` (None: not yet)."""
        return self.loop.tunes.acked(seq)

    def bind(self, supervisor: Supervisor) -> None:
        self.supervisor = supervisor
        supervisor.unit = self

    # ---- the control thread ---------------------------------------------------------------
    def start_control(self, enter_rt: EnterRealtime, priority: int) -> None:
        """Start the control thread (SCHED_FIFO `priority` through `enter_rt`); return once it
        has ticked: the resource is held by its Hold task. `ControlThreadError` if it ended or
        did not tick within `HOLDING_WAIT_S`."""
        self._enter_rt, self._priority = enter_rt, priority
        self._start_and_wait()

    def restart_control(self) -> None:
        """The control thread again, after it failed (a reset's first step); as `start_control`."""
        if not self.control_ended():
            return
        if self._enter_rt is None:
            raise ControlThreadError(f"{self.name}: its control thread was never started")
        self._start_and_wait()

    def _start_and_wait(self) -> None:
        ticks = int(self.tel.header[H.TICKS])
        failures = self.failures
        self.failure = ""
        self.stalled = ""
        self._started_ns = time.monotonic_ns()
        self._control = self.threads.start(self._control_main, name="control")
        end = time.monotonic() + HOLDING_WAIT_S
        while int(self.tel.header[H.TICKS]) == ticks:
            if self.failures != failures:
                raise ControlThreadError(f"{self.name}: {self.failure}")
            if time.monotonic() > end:
                raise ControlThreadError(
                    f"{self.name}: its control thread did not tick within {HOLDING_WAIT_S:g} s"
                )
            time.sleep(0.001)

    def control_running(self) -> bool:
        return self._control is not None and self._control.is_alive()

    def control_ended(self) -> bool:
        """Its control thread was started and has ended (it failed, or the unit was stopped)."""
        return self._control is not None and not self._control.is_alive()

    def still_stalled(self) -> str:
        """Why a reset must wait: the control thread hung and not ticking again yet ("" if not)."""
        control = self._control
        if not self.stalled or control is None or not control.is_alive():
            return ""
        if self.heartbeat_fresh(time.monotonic_ns()):
            return ""  # it came back (the call returned): the loop ticks, safe-stopped
        line = line_of(control)
        return "its control loop still does not tick" + (f" (waiting at {line})" if line else "")

    def _control_main(self) -> None:
        assert self._enter_rt is not None
        rt = self._enter_rt(self._priority)
        rt.gc_frozen = False  # the collector stays frozen for the process: the others still tick
        for w in rt.warnings:
            log.warning("control thread of %s: %s", self.name, w)
        try:
            self.loop.executor.run()
        except BaseException as e:
            self._failed(f"its control thread failed: {type(e).__name__}: {e}")
            log.exception("control thread of %s failed", self.name)
        finally:
            leave_realtime(rt)

    def _failed(self, why: str) -> None:
        """The control thread's last act: the resource's own safe stop, why, the automaton told."""
        try:
            self.resource.safe_stop()
        except Exception:
            log.exception("%s: safe stop after its control thread failed", self.name)
        self.failure = why
        self.failures += 1
        try:
            self.on_failure(why)
        except Exception:
            log.exception("%s: telling that its control thread failed", self.name)
        with contextlib.suppress(OSError):
            os.write(self.wake_fd, b"x")

    def device_reset(self, wait_s: float) -> _DeviceReset:
        """A reset's device work, on a thread of the unit (the control thread started again
        first if it had ended)."""
        restart = self.restart_control if self.control_ended() else None
        return _DeviceReset(self.threads, self.resource, self.loop, wait_s, restart)

    def raise_failure(self, t_s: float, why: str) -> bool:
        """The automaton thread's, once the control thread has ended on `why`: its active task's
        type 3 `LawError`, queued as its tick would have (this thread is the queue's only
        producer now). False if there is no task to raise it (none active, or already faulted)."""
        task = self.loop.active
        if task is None or task.phase is Phase.FAULT:
            return False
        task.raise_t3(t_s, "LawError", why)
        return True

    def failure_pending(self) -> bool:
        """A failure `take_failure` has not taken yet."""
        return self.failures != self._failures_taken

    def take_failure(self) -> str:
        """The automaton thread's: why the control thread ended, once per failure ("" if not)."""
        if self.failures == self._failures_taken:
            return ""
        self._failures_taken = self.failures
        return self.failure

    # ---- health and the end ---------------------------------------------------------------
    def heartbeat_fresh(self, now_ns: int) -> bool:
        """The control loop ticked within its watchdog's periods."""
        return heartbeat_fresh(self.cfg, self.tel, now_ns)

    def check_stall(self, now_ns: int) -> str:
        """The automaton thread's, at each wake-up: why the control thread is hung, the first time
        it is found so ("" otherwise): running, no tick for `stall_after_s` since its last tick or
        its start. Its resource's safe stop then starts on a thread of the unit."""
        control = self._control
        if self.stalled or control is None or not control.is_alive():
            return ""
        quiet_s = stalled_for_s(self.cfg, self.tel, self._started_ns, now_ns)
        if not quiet_s:
            return ""
        line = line_of(control)
        self.stalled = f"its control loop has not ticked for {quiet_s:.2f} s" + (
            f" (waiting at {line})" if line else ""
        )
        self.threads.start(self.stop_stalled, name="stall-safe-stop")
        return self.stalled

    def control_line(self) -> str:
        """The line the control thread is at outside the standard library ("": not running)."""
        control = self._control
        return line_of(control) if control is not None and control.is_alive() else ""

    def stop_stalled(self) -> None:
        try:
            self.resource.safe_stop()
        except Exception:
            log.exception("%s: safe stop of a stalled resource", self.name)

    def stop(self) -> None:
        """The control loop returns after its current tick."""
        self.loop.executor.stop()

    def join(self, timeout_s: float) -> list[str]:
        """Every thread of the unit ended (the output thread once its queue is done), waited for
        `timeout_s` in all; the names of those still running (a device call that hangs)."""
        self.outputs.close()
        return self.threads.join(timeout_s)
