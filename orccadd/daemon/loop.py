"""The daemon's control thread: tick the active Robot-Task, switch at tick boundaries, publish.

The automaton thread never touches a task the control thread is ticking: it posts a switch
request (a sequence number and the task) and the control thread applies it at the start of
its next tick. The new task initialises from the measured state and continues the outgoing
task's command (`RobotTask.continue_from`), so the arm is never left without a fresh command.
"""

from __future__ import annotations

import contextlib
import os
import select
import time

from orccadd.daemon.telemetry import TICK_FIELDS, H, TelemetryBlock
from orccadd.physres.base import PhysicalResource
from orccadd.runtime.clock import Clock
from orccadd.runtime.control import ControlLoop
from orccadd.task.events import EventQueue
from orccadd.task.task import RobotTask

NF = len(TICK_FIELDS)


class SwitchingLoop(ControlLoop):
    """`ControlLoop` plus the switch mailbox, per-tick telemetry and event notification."""

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
        self.wake_fd = wake_fd
        self.blend_ticks = blend_ticks
        self.task_ids: dict[int, int] = {id(hold): 0}  # id(task) -> telemetry task id
        self._request: tuple[int, RobotTask] = (0, hold)
        self._applied = -1
        self._notified = 0
        self.switches = 0
        self.busy_ns = 0  # fault injection: extra compute per tick (real overruns)
        self.busy_ticks = 0
        self._slack_r, self._slack_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self._slack_wanted = False

    # ---- the automaton thread's side -------------------------------------------------------
    @property
    def pending_task(self) -> RobotTask:
        """The task of the last switch request (applied or not)."""
        return self._request[1]

    def request_switch(self, task: RobotTask) -> None:
        """Make `task` the active one at the next tick (restarted if it already is)."""
        self._request = (self._request[0] + 1, task)

    def wait_for_slack(self, timeout_s: float) -> bool:
        """Block until the control thread has just finished a tick (False after `timeout_s`:
        the loop is stopped or late, so there is nothing to keep out of the way of)."""
        with contextlib.suppress(BlockingIOError):
            os.read(self._slack_r, 64)
        self._slack_wanted = True
        ready, _, _ = select.select([self._slack_r], [], [], timeout_s)
        self._slack_wanted = False
        with contextlib.suppress(BlockingIOError):
            os.read(self._slack_r, 64)
        return bool(ready)

    # ---- the control thread ---------------------------------------------------------------
    def step(self, t_s: float) -> None:
        req = self._request
        if req[0] != self._applied:
            self._applied = req[0]
            self._switch(req[1])
        task = self.active
        assert task is not None
        task.tick(t_s)
        if self.busy_ticks:
            self.busy_ticks -= 1
            end = time.perf_counter_ns() + self.busy_ns
            while time.perf_counter_ns() < end:
                pass
        self._publish(t_s, task)
        pushed = self.queue.pushed
        if pushed != self._notified:
            self._notified = pushed
            with contextlib.suppress(BlockingIOError):  # wake-ups already pending
                os.write(self.wake_fd, b"e")
        if self._slack_wanted:
            self._slack_wanted = False
            with contextlib.suppress(BlockingIOError):
                os.write(self._slack_w, b"s")

    def _switch(self, new: RobotTask) -> None:
        old = self.active
        res = self.resource
        mode = new.signature.command
        continues = old is not None and old.wrote and old.signature.command is mode
        if old is not None and old is not new:
            old.deactivate()
        if mode is not res.mode:
            res.switch_mode(mode)
        new.activate()
        if continues and old is not None:
            new.continue_from(old.sent, self.blend_ticks)
        self.active = new
        self.switches += 1

    def _publish(self, t_s: float, task: RobotTask) -> None:
        tel, st, stats = self.tel, self.resource.state, self.stats
        rec = tel.begin_tick()
        rec[1] = t_s
        rec[2] = stats.last_latency_ns * 1e-3
        rec[3] = stats.last_compute_ns * 1e-3
        rec[4] = self.task_ids.get(id(task), -1)
        rec[5] = task.phase
        rec[6] = task.wrote
        rec[7] = st.status
        n = st.q_rad.shape[0]
        rec[NF : NF + n] = st.q_rad
        rec[NF + n : NF + 2 * n] = st.dq_rad_s
        rec[NF + 2 * n : NF + 3 * n] = st.tau_nm
        rec[NF + 3 * n : NF + 4 * n] = task.sent
        hdr = tel.header
        hdr[H.TICKS] = stats.ticks
        hdr[H.OVERRUNS] = stats.overruns
        hdr[H.CONSECUTIVE_OVERRUNS] = stats.consecutive_overruns
        hdr[H.SWITCHES] = self.switches
        tel.commit_tick(rec, time.monotonic_ns())
