"""The daemon's control thread: tick the active Robot-Task, switch at tick boundaries, publish.

The automaton thread never touches a task the control thread is ticking. It posts:

- a switch request (a sequence number and the task), applied at the start of the next tick; the
  new task initialises from the measured state and continues the outgoing task's command
  (`RobotTask.continue_from`), so the arm is never left without a fresh command; a position
  command in its position and velocity too (the new law starts from the command's motion);
- parameter changes, through a single-producer/single-consumer mailbox: applied at the start of
  the next tick, in order, each acknowledged with that tick's number (its telemetry record);
- a wish for slack: after the next tick ends, the control thread writes a byte to `slack_fd`,
  so the automaton thread's work (commands) starts when a whole period lies ahead.
"""

from __future__ import annotations

import contextlib
import os
import struct
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from orccadd.modules.base import CommandMotion
from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import tick_signals
from orccadd.runtime.clock import Clock
from orccadd.runtime.mailbox import Mailbox
from orccadd.task.events import EventQueue
from orccadd.task.loop import ControlLoop
from orccadd.task.task import ParameterChange, RobotTask
from orccadd.vec import float_view
from orccadd.wire.schema import H, T, TickLayout
from orccadd.wire.telemetry import TelemetryBlock


class TickReactor(Protocol):
    """Reacts to a tick's events within the tick (`orccadd.daemon.inline.InlineReactor`)."""

    def react(
        self,
        loop: SwitchingLoop,
        t_s: float,
        first: int,
        end: int,
        active: RobotTask,
        switch: Callable[[RobotTask], None],
    ) -> bool: ...


class SwitchingLoop(ControlLoop):
    """`ControlLoop` plus the switch and tune mailboxes, per-tick telemetry and notifications."""

    def __init__(
        self,
        resource: PhysicalResource,
        clock: Clock,
        hold: RobotTask,
        queue: EventQueue,
        telemetry: TelemetryBlock,
        wake_fd: int,
        *,
        overrun_limit: int,
        blend_ticks: int,
    ) -> None:
        super().__init__(resource, clock, overrun_limit=overrun_limit)
        self.hold = hold
        self.queue = queue
        self.tel = telemetry
        self.layout = TickLayout(telemetry.dof, tick_signals(resource.description.signals))
        if self.layout.width != telemetry.ticks.shape[1]:
            raise ValueError(
                f"telemetry block of {telemetry.ticks.shape[1]} values a tick for a record of "
                f"{self.layout.width} (its Layout's extra: the resource's signals)"
            )
        # the resource's own signals, copied into each tick's record after the joint vectors
        self._signals = tuple(
            (self.layout.signals[g.name], resource.signals[g.name]) for g in resource.description.signals
        )
        # each tick's record is written into `TelemetryBlock.words`, faster than through numpy:
        # its scalar fields (`T` after SEQ, in order) and the header's counters (`H.TICKS` to
        # `H.SWITCHES`) each by one struct (byte offsets: 8 a word), its vectors through
        # memoryviews, as (first word, end, values): q, dq and tau in one copy
        # (`JointState.vector`'s order), the command sent, the resource's signals
        self._pack_fields = struct.Struct(f"{len(T) - 1}d").pack_into
        self._pack_counters = struct.Struct(f"{H.SWITCHES - H.TICKS + 1}d").pack_into
        self._counters_at = 8 * int(H.TICKS)
        at = self.layout
        self._vectors = (
            (at.q.start, at.tau.stop, float_view(resource.state.vector)),
            (at.cmd.start, at.cmd.stop, float_view(resource.last_command)),
            *((where.start, where.stop, float_view(value)) for where, value in self._signals),
        )
        self.wake_fd = wake_fd
        self.blend_ticks = blend_ticks
        self.tunes: Mailbox[ParameterChange] = Mailbox(64)
        self._task_ids: dict[int, int] = {id(hold): 0}  # id(task) -> telemetry task id
        # the event id of each of the resource's named inputs the mission declares (-1: not)
        self._input_events: tuple[int, ...] = ()
        self._request: tuple[int, RobotTask, bool] = (0, hold, False)
        self._applied = -1
        self._notified = 0
        self.switches = 0
        self._busy_ns = 0  # fault injection: extra compute per tick (real overruns)
        self._busy_ticks = 0
        # fault injection at the next tick's start (one test a tick): ("fail", 0) raises (the
        # thread ends), ("hang", s) waits s seconds (a device call that does not return)
        self._injection: tuple[str, float] | None = None
        self._stop_wanted = False
        self._slack_r, self._slack_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self._slack_wanted = False
        self.reactor: TickReactor | None = None  # reacts to a tick's events in that tick
        self.switches_in_tick = 0
        self._t_s = 0.0
        self._motion = CommandMotion(resource.model.dof)  # the outgoing command's, at a switch

    # ---- the automaton thread's side -------------------------------------------------------
    @property
    def pending_task(self) -> RobotTask:
        """The task of the last switch request (applied or not)."""
        return self._request[1]

    def request_switch(self, task: RobotTask, fresh: bool = False) -> int:
        """Make `task` the active one at the next tick (restarted if it already is). `fresh`:
        from the measured state, not blended from the outgoing task's last command (after a
        safe stop and a reset, that command is stale: the arm may be elsewhere)."""
        self._request = (self._request[0] + 1, task, fresh)
        return self._request[0]

    def switched(self, request: int) -> bool:
        """The control thread has applied switch request `request` (or a later one)."""
        return self._applied >= request

    def set_input_events(self, ids: tuple[int, ...]) -> None:
        """Per named input of the resource (`description.inputs`), the event its rising edge
        pushes (-1: the mission does not declare it). One store: the old or the new tuple."""
        self._input_events = ids

    def set_tasks(self, tasks: Sequence[RobotTask]) -> None:
        """The tasks by telemetry id (their position: `MissionControl.tasks`)."""
        self.set_task_ids({id(t): i for i, t in enumerate(tasks)})

    def set_task_ids(self, ids: dict[int, int]) -> None:
        """Telemetry task ids by id(task) (`MissionControl.tasks`: the Hold tasks, then the
        mission's)."""
        self._task_ids = dict(ids)  # one store: the control thread sees the old or the new dict

    def inject_overrun(self, ticks: int, extra_ns: int) -> None:
        """Fault injection: spin `extra_ns` more in each of the next `ticks` ticks."""
        self._busy_ns = extra_ns
        self._busy_ticks = ticks

    def inject_failure(self) -> None:
        """Fault injection: the next tick raises, ending the control thread (a bug's effect)."""
        self._injection = ("fail", 0.0)

    def inject_hang(self, seconds: float) -> None:
        """Fault injection: the next tick waits `seconds` before it reads, as a device call that
        does not return would (releasing the interpreter, as a blocked read does)."""
        self._injection = ("hang", seconds)

    @property
    def slack_fd(self) -> int:
        """Readable once a tick has ended after the last `want_slack()`."""
        return self._slack_r

    def request_safe_stop(self) -> None:
        """Safe-stop the resource at the start of the next tick, from the control thread (the
        thread that talks to the device), whatever the automaton thread is doing then."""
        self._stop_wanted = True

    def want_slack(self) -> None:
        with contextlib.suppress(BlockingIOError):
            os.read(self._slack_r, 64)
        self._slack_wanted = True

    def close(self) -> None:
        os.close(self._slack_r)
        os.close(self._slack_w)

    # ---- the control thread ---------------------------------------------------------------
    def step(self, t_s: float) -> None:
        self._t_s = t_s
        if self._injection is not None:
            self._inject()
        if self._stop_wanted:
            self._stop_wanted = False
            self.resource.safe_stop()
        if self.tunes.waiting:
            self.tunes.drain(RobotTask.apply_change, int(self.tel.header[H.TICK_HEAD]) + 1)
        req = self._request
        if req[0] != self._applied:
            self._applied = req[0]
            self._switch(req[1], req[2])
        task = self.active
        assert task is not None
        first = self.queue.pushed
        task.compute(t_s)
        rose = self.resource.take_rising()
        if rose and self._input_events:  # read in this tick: the automaton reacts in it too
            for i, eid in enumerate(self._input_events):
                if rose >> i & 1 and eid >= 0:
                    self.queue.push(t_s, eid)
        end = self.queue.pushed
        reactor = self.reactor  # the automaton's reaction to this tick's events, in this tick
        if end != first and reactor and reactor.react(self, t_s, first, end, task, self._switch_in_tick):
            task = self.active
            assert task is not None
        task.commit(t_s)
        if self._busy_ticks:
            self._busy_ticks -= 1
            end = time.perf_counter_ns() + self._busy_ns
            while time.perf_counter_ns() < end:
                pass
        pushed = self.queue.pushed
        if pushed != self._notified:
            self._notified = pushed
            with contextlib.suppress(BlockingIOError):  # wake-ups already pending
                os.write(self.wake_fd, b"e")

    def _inject(self) -> None:
        """The injected fault of this tick (the rare path)."""
        kind, seconds = self._injection or ("", 0.0)
        self._injection = None
        if kind == "fail":
            raise RuntimeError("injected failure of the control thread")
        time.sleep(seconds)  # releases the interpreter, as a blocked read does

    def requests_applied(self) -> bool:
        """Every switch request applied (read by any thread)."""
        return self._request[0] == self._applied

    def _switch_in_tick(self, new: RobotTask) -> None:
        """The automaton reacted in this tick (`InlineReactor`): the new law computes its
        command from the state this tick has read, and `commit` sends it."""
        self._switch(new, in_tick=True)
        self.switches_in_tick += 1
        new.compute(self._t_s, read=False)

    def _switch(self, new: RobotTask, fresh: bool = False, in_tick: bool = False) -> None:
        old = self.active
        res = self.resource
        mode = new.signature.command
        # the outgoing task's command of the last tick (in the tick: `compute` has begun this one)
        wrote = old is not None and (old.wrote_before if in_tick else old.wrote)
        continues = not fresh and wrote and old is not None and old.signature.command is mode
        # a position command's motion, read before `activate` (a restarted task clears its own)
        moving = continues and old is not None and old.command_motion(self._motion)
        # the resource's faults the arm is safe-stopped for, already raised: not raised again
        reported = old.reported_t3 if old is not None and res.stopping_or_stopped else 0
        if old is not None and old is not new:
            old.deactivate()
        if mode is not res.mode:
            res.perform_mode_switch(mode)
        new.activate()
        new.reported_t3 = reported
        if continues and old is not None:
            new.continue_from(old.sent, self.blend_ticks, self._motion if moving else None)
        self.active = new
        self.switches += 1

    def after_step(self, t_s: float) -> None:
        """The tick's telemetry record, with this tick's own wake-up and compute time."""
        tel, res, stats, task = self.tel, self.resource, self.stats, self.active
        assert task is not None
        w = tel.words
        at = tel.begin_tick_at()
        self._pack_fields(  # T_S, WAKE_US, COMPUTE_US, TASK, PHASE, WROTE, STATUS, MODE
            w,
            8 * (at + 1),
            t_s,
            stats.last_latency_ns * 1e-3,
            stats.last_compute_ns * 1e-3,
            self._task_ids.get(id(task), -1),
            task.phase,
            task.wrote,
            res.state.status,
            res.mode,
        )
        for start, end, values in self._vectors:
            w[at + start : at + end] = values
        self._pack_counters(  # TICKS, OVERRUNS, CONSECUTIVE_OVERRUNS, SWITCHES
            w, self._counters_at, stats.ticks, stats.overruns, stats.consecutive_overruns, self.switches
        )
        tel.commit_tick_at(at, time.monotonic_ns())
        if self._slack_wanted:  # the tick is over and published: a period lies ahead
            self._slack_wanted = False
            with contextlib.suppress(BlockingIOError):
                os.write(self._slack_w, b"s")
