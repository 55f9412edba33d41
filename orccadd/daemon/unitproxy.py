"""A resource's unit as the automaton's process sees it when the unit runs in a process of its
own (`unitproc`): the same surface as `ResourceUnit` (its `loop`, `resource`, `queue`,
`outputs`, control-thread health, reset), each part backed by the unit's channel (switches,
events, stop requests), its telemetry block (state, active task, heartbeat) or its link
(missions, tunes, outputs, resets, injections; answers polled, never waited for in a tick of
the automaton's work).

The automaton's process keeps, per resource, a *shadow*: the backend's resource built from the
config and never configured (no bus opened). The mission's tasks are built on it as in one
process, which gives every task, parameter and event the same name and id as in the unit
(`EventRegistry` seeded the same way on both sides); the shadow's state is the unit's last tick,
read from the telemetry block at each `refresh`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import time
from collections.abc import Callable, Sequence
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.daemon.replies import CommandError
from orccadd.daemon.unit import heartbeat_fresh, hold_task, stalled_for_s
from orccadd.daemon.unitlink import UnitLink, UnitLinkError
from orccadd.daemon.unitshm import UnitChannel
from orccadd.errors import OrccaddError
from orccadd.fault import Fault, FaultKind
from orccadd.physres.base import Diagnostics, PhysicalResource
from orccadd.runtime.clock import Clock, WallClock
from orccadd.runtime.threads import ThreadGroup
from orccadd.state import JointState
from orccadd.task import EventQueue, EventRegistry, RobotTask
from orccadd.task.task import ParameterChange
from orccadd.types import CommandMode, Status
from orccadd.wire.schema import H, T, TickLayout
from orccadd.wire.telemetry import TelemetryBlock

log = logging.getLogger("orccadd")
REPLY_WAIT_S = 5.0  # the longest a unit's answer to a short request may take
STALL_ANSWER_S = 0.2  # how long a stalled unit's answer (where it waits) is waited for


class RemoteQueue:
    """The unit's event ring, as the automaton's `EventQueue` (its consumer's side)."""

    def __init__(self, channel: UnitChannel) -> None:
        self.channel = channel

    @property
    def pushed(self) -> int:
        return self.channel.pushed

    @property
    def tail(self) -> int:
        return self.channel.tail

    @property
    def dropped(self) -> int:
        return self.channel.lost

    def event_at(self, index: int) -> int:
        return int(self.channel.ring[index % self.channel.ring_len][1])

    def drain(self) -> list[tuple[float, int]]:
        return [(e.t_s, e.event_id) for e in self.channel.drain()]

    def push(self, t_s: float, event_id: int) -> None:
        """The automaton's own event for this resource (a failed or dead unit's last type 3)."""
        self.channel.push(t_s, event_id)


class RemoteTunes:
    """The unit's tune mailbox: a change posted to the unit, acknowledged with its tick."""

    def __init__(self, proxy: UnitProxy) -> None:
        self.proxy = proxy
        self._acked: dict[int, int] = {}
        self._refused: dict[int, str] = {}
        self.waiting = 0

    def post(self, change: ParameterChange, task: int, path: str, value: Any) -> int:
        rid = self.proxy.request("tune", task=task, path=path, value=value)
        self.waiting += 1

        def answered(msg: dict[str, Any]) -> None:
            self.waiting -= 1
            if "tick" in msg:
                self._acked[rid] = int(msg["tick"])
                RobotTask.apply_change(change)  # the shadow's parameter: the next tune's "previous"
            else:
                self._refused[rid] = str(msg.get("error", "refused"))

        self.proxy.on_answer(rid, answered)
        return rid

    def acked(self, seq: int) -> int | None:
        """The tick that applied tune `seq` (None: not yet); `CommandError` if the unit refused."""
        self.proxy.pump()
        if seq in self._refused:
            raise CommandError(f"tune: the unit of {self.proxy.name} refused it: {self._refused.pop(seq)}")
        return self._acked.pop(seq, None)


class RemoteLoop:
    """The unit's control loop, as the automaton thread uses a `SwitchingLoop`."""

    def __init__(self, proxy: UnitProxy, hold: RobotTask) -> None:
        self.proxy = proxy
        self.channel = proxy.channel
        self.hold = hold
        self.resource = proxy.resource
        self.queue = proxy.queue
        self.tunes = RemoteTunes(proxy)
        self.reactor: Any = None
        self._ids: dict[int, int] = {id(hold): 0}
        self._by_id: list[RobotTask] = [hold]
        self._pending: RobotTask = hold
        self.input_events: tuple[int, ...] = ()
        # always readable: the automaton's work needs no slack from a loop in another process
        # (it holds no interpreter lock that loop waits for)
        self._slack_r, self._slack_w = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        os.write(self._slack_w, b"s")

    @property
    def slack_fd(self) -> int:
        return self._slack_r

    def want_slack(self) -> None:
        pass

    # ---- as `SwitchingLoop`'s automaton side ------------------------------------------------
    @property
    def active(self) -> RobotTask | None:
        """The task the unit ticked last (by its telemetry id)."""
        i = self.proxy.last_task_id()
        return self._by_id[i] if 0 <= i < len(self._by_id) else None

    @property
    def pending_task(self) -> RobotTask:
        return self._pending

    def task_id(self, task: RobotTask) -> int:
        return self._ids[id(task)]

    def request_switch(self, task: RobotTask, fresh: bool = False) -> int:
        self._pending = task
        return self.channel.request_switch(self._ids[id(task)], fresh)

    def switched(self, request: int) -> bool:
        return self.channel.switched(request)

    def requests_applied(self) -> bool:
        return self.channel.requests_applied()

    def set_tasks(self, tasks: Sequence[RobotTask]) -> None:
        """The automaton's task list (`MissionControl.tasks`: ids by position, the unit's too)."""
        self._by_id = list(tasks)
        self._ids = {id(t): i for i, t in enumerate(tasks)}

    def set_input_events(self, ids: tuple[int, ...]) -> None:
        self.input_events = ids

    def request_safe_stop(self) -> None:
        self.channel.request_stop()

    def inject_failure(self) -> None:
        self.proxy.call("inject", kind="control_thread")

    def inject_hang(self, seconds: float) -> None:
        self.proxy.call("inject", kind="hang", seconds=seconds)

    def inject_crash(self) -> None:
        """The unit's process dies at once (`os._exit`), as a driver's segfault would end it."""
        self.proxy.request("inject", kind="crash")

    def inject_overrun(self, ticks: int, extra_ns: int) -> None:
        self.proxy.call("inject", kind="overrun", ticks=ticks, extra_ns=extra_ns)

    def close(self) -> None:
        os.close(self._slack_r)
        os.close(self._slack_w)


class ResourceView:
    """The resource as the automaton's process sees it: its shadow's config, model and
    description, its state from the unit's last tick; its actions asked of the unit."""

    def __init__(self, proxy: UnitProxy, shadow: PhysicalResource) -> None:
        self.proxy = proxy
        self.shadow = shadow
        self.config = shadow.config
        self.model = shadow.model
        self.description = shadow.description
        self.supported_modes = shadow.supported_modes
        self.name = shadow.name
        self.dof = shadow.dof
        self.state = JointState(self.dof)
        self.mode = CommandMode.TORQUE
        self.diagnostics_cache: Diagnostics | None = None
        self.fault_text = ""

    @property
    def stopping_or_stopped(self) -> bool:
        return bool(int(self.state.status) & int(Status.STOPPING | Status.STOPPED))

    @property
    def fault_message(self) -> str:
        """The device's last fault in words, as the unit last said it ("" if none)."""
        return self.fault_text

    def helper_pid(self) -> int:
        return int(self.proxy.holding.get("helper_pid", 0))

    def safe_stop(self) -> None:
        self.proxy.channel.request_stop()

    def inject_fault(self, kind: str, message: str) -> None:
        try:
            self.proxy.call("inject", kind="resource", fault=kind, message=message)
        except UnitLinkError as e:
            raise OrccaddError(str(e)) from None

    def diagnostics(self) -> Diagnostics:
        """The unit's resource's, asked for briefly (a unit that does not answer at once: the
        last it gave, or the shadow's)."""
        try:
            answer = self.proxy.link.call("diagnostics", timeout_s=STALL_ANSWER_S)
            d = answer["diagnostics"]
            assert isinstance(d, Diagnostics)
            self.diagnostics_cache, self.fault_text = d, str(answer.get("fault", ""))
        except UnitLinkError:
            pass
        return self.diagnostics_cache if self.diagnostics_cache is not None else self.shadow.diagnostics()


class RemoteReset:
    """A reset's device work, done by the unit (as `supervision._DeviceReset`). A unit whose
    process has ended is started again instead: a new process configures the resource and holds
    it (a fresh start is a reset), then builds the loaded mission's tasks again."""

    def __init__(self, proxy: UnitProxy, wait_s: float) -> None:
        self.proxy = proxy
        self._started = time.monotonic()
        self._error = ""
        self._ended = False
        if proxy.link.proc.poll() is None:
            self.step = "the device's reset, in the unit"
            proxy.on_answer(proxy.request("reset", wait_s=wait_s), self._answered)
        else:
            self.step = "starting its unit process again"
            proxy.link = proxy.link.again()

    def _answered(self, msg: dict[str, Any]) -> None:
        self._error = str(msg.get("error", ""))
        self._ended = True

    def running(self) -> bool:
        p = self.proxy
        p.pump()
        if self._ended:
            return False
        if self.step.startswith("starting"):
            if p.link.refused or p.link.proc.poll() is not None:
                self._answered(
                    {"error": f"{p.name}: its unit process did not start: {p.link.refused or 'it ended'}"}
                )
            elif p.link.holding:
                if p.mission_message is None:
                    self._ended = True
                else:
                    self.step = "the mission's tasks built again in the new unit process"
                    message = {**p.mission_message, "registry": p.registry.infos()}
                    p.on_answer(p.request("load", **message), self._answered)
        return not self._ended

    def where(self) -> str:
        return f"for {time.monotonic() - self._started:.0f} s, in {self.step}"

    def done(self) -> bool:
        if self.running():
            return False
        if self._error:
            raise CommandError(f"the reset of {self.proxy.name} failed in {self.step}: {self._error}")
        self.proxy.failure = ""
        self.proxy.stalled = ""
        return True


class RemoteOutputs:
    """The unit's output actions (`emit R.Y`): asked of it, performed in its own time."""

    def __init__(self, proxy: UnitProxy) -> None:
        self.proxy = proxy

    def request(self, name: str) -> None:
        self.proxy.request("output", name=name)

    def close(self) -> None:
        pass


class UnitProxy:
    """One resource's unit in a process of its own, seen from the automaton's process."""

    def __init__(
        self,
        cfg: RobotConfig,
        shadow: PhysicalResource,
        tel: TelemetryBlock,
        registry: EventRegistry,
        link: UnitLink,
        *,
        hold_name: str,
    ) -> None:
        """`shadow`: the resource built and never configured (the tasks are built on it, as in
        the unit); `link`: the unit process, started."""
        self.cfg = cfg
        self.link = link
        self.channel = link.channel
        self.tel = tel
        self.registry = registry
        self.queue = RemoteQueue(self.channel)
        self.resource = ResourceView(self, shadow)
        self.shadow = shadow
        self.task_resource: PhysicalResource = shadow  # what the automaton's tasks are built on
        self.task_queue = EventQueue(1)  # theirs: never ticked here, they push nothing
        self.clock: Clock = WallClock()
        self.loop = RemoteLoop(self, hold_task(cfg, shadow, registry, self.task_queue, hold_name))
        self.outputs = RemoteOutputs(self)
        self.threads = ThreadGroup(f"unit-{shadow.name}", daemon=False)  # none: the unit's are its own
        self.supervisor: Any = None
        self.failure = ""
        self.failures = 0
        self._failures_taken = 0
        self.stalled = ""
        self._started_ns = 0
        self._answers: dict[int, Callable[[dict[str, Any]], None]] = {}
        self.mission_message: dict[str, Any] | None = None  # the last mission the unit built
        layout = TickLayout(tel.dof, ())
        self._q = slice(layout.q.start, layout.tau.stop)

    @property
    def name(self) -> str:
        return self.shadow.name

    @property
    def pid(self) -> int:
        """The unit's process."""
        return int(self.link.proc.pid)

    @property
    def holding(self) -> dict[str, Any]:
        return self.link.holding

    def bind(self, supervisor: Any) -> None:
        self.supervisor = supervisor
        supervisor.unit = self

    # ---- the link -------------------------------------------------------------------------
    def request(self, op: str, **args: Any) -> int:
        return self.link.send(op, **args)

    def on_answer(self, rid: int, then: Callable[[dict[str, Any]], None]) -> None:
        self._answers[rid] = then

    def call(self, op: str, **args: Any) -> dict[str, Any]:
        """A short request, waited for (`REPLY_WAIT_S` at most: the unit's link thread answers
        it at once); `UnitLinkError` if refused or not answered."""
        return self.link.call(op, timeout_s=REPLY_WAIT_S, **args)

    def pump(self) -> None:
        """Every message the unit has sent: answers to their callers, `failed` recorded, a type
        3's fault given to the shadow task (before the automaton drains its event: the unit
        sends it first); the unit's process ended: its failure."""
        try:
            messages = self.link.receive(0.0)
        except UnitLinkError as e:
            messages = []
            if not self.failure:
                self._control_failed(str(e))
        for msg in messages:
            rid = msg.get("id")
            if rid in self._answers:
                self._answers.pop(rid)(msg)
            elif msg.get("op") == "failed":
                self._control_failed(str(msg.get("why", "")))
            elif msg.get("op") == "t3":
                task = next((t for t in self.loop._by_id if t.name == msg["task"]), None)
                if task is not None:
                    task.fault = msg["fault"]

    def _control_failed(self, why: str) -> None:
        self.failure = why
        self.failures += 1

    # ---- the state, from the telemetry block ----------------------------------------------
    def last_task_id(self) -> int:
        tel = self.tel
        head = int(tel.header[H.TICK_HEAD])
        return int(tel.ticks[(head - 1) % len(tel.ticks), T.TASK]) if head else 0

    def refresh(self) -> None:
        """The view's state from the unit's last tick (the automaton thread's, at each wake)."""
        tel = self.tel
        head = int(tel.header[H.TICK_HEAD])
        if not head:
            return
        rec = tel.ticks[(head - 1) % len(tel.ticks)]
        st = self.resource.state
        st.vector[:] = rec[self._q]
        st.status = int(rec[T.STATUS])
        self.resource.mode = CommandMode(int(rec[T.MODE]))
        self.pump()

    # ---- as `ResourceUnit` ----------------------------------------------------------------
    def start_control(self, enter_rt: Any, priority: int) -> None:
        self._started_ns = time.monotonic_ns()
        try:
            self.link.wait_holding()
        except UnitLinkError as e:
            raise OrccaddError(str(e)) from None
        self.refresh()

    def control_running(self) -> bool:
        return self.link.proc.poll() is None and not self.failure

    def control_ended(self) -> bool:
        return not self.control_running()

    def still_stalled(self) -> str:
        if not self.stalled or not self.control_running():
            return ""
        return "" if self.heartbeat_fresh(time.monotonic_ns()) else "its control loop still does not tick"

    def failure_pending(self) -> bool:
        return self.failures != self._failures_taken

    def take_failure(self) -> str:
        self.pump()
        if self.failures == self._failures_taken:
            return ""
        self._failures_taken = self.failures
        return self.failure

    def heartbeat_fresh(self, now_ns: int) -> bool:
        return heartbeat_fresh(self.cfg, self.tel, now_ns)

    def check_stall(self, now_ns: int) -> str:
        """As `ResourceUnit.check_stall`, the unit's safe stop asked of it."""
        if self.stalled or not self.control_running():
            return ""
        quiet_s = stalled_for_s(self.cfg, self.tel, self._started_ns, now_ns)
        if not quiet_s:
            return ""
        # the unit safe-stops its resource from a thread of its own and says where its control
        # thread waits (not waited for long: a unit hung whole answers nothing)
        try:
            line = str(self.link.call("stalled", timeout_s=STALL_ANSWER_S).get("line", ""))
        except UnitLinkError:
            line = ""
        self.stalled = f"its control loop has not ticked for {quiet_s:.2f} s" + (
            f" (waiting at {line})" if line else ""
        )
        return self.stalled

    def post_tune(self, task: RobotTask, path: str, value: Any, change: ParameterChange) -> int:
        """The tune to the unit, which checks it again on its own task and applies it at a
        tick boundary; a sequence number for `tune_acked`."""
        return self.loop.tunes.post(change, self.loop.task_id(task), path, value)

    def tune_acked(self, seq: int) -> int | None:
        return self.loop.tunes.acked(seq)

    def raise_failure(self, t_s: float, why: str) -> bool:
        """The unit's control thread (or process) ended on `why`, its resource safe-stopped by
        it (or by the device's watchdog): its active task's type 3 `LawError`, pushed here into
        the unit's ring, which nothing else writes now."""
        task = self.loop.active
        if task is None:
            return False
        task.fault_reason = "LawError"
        task.fault = Fault(FaultKind.INTERNAL, self.name, why)
        self.queue.push(t_s, task.builtin_ids["LawError"])
        return True

    def load_mission(self, message: dict[str, Any]) -> None:
        """The mission's tasks built in the unit as here (`message`: what `unitproc` takes);
        `OrccaddError` with its words if the unit refused. Kept: a unit started again builds
        them too."""
        try:
            self.link.call("load", timeout_s=REPLY_WAIT_S, registry=self.registry.infos(), **message)
        except UnitLinkError as e:
            raise OrccaddError(str(e)) from None
        self.mission_message = message

    def device_reset(self, wait_s: float) -> RemoteReset:
        return RemoteReset(self, wait_s)

    def stop(self) -> None:
        """The unit ends: its safe stop, its loop, its resource released."""
        with contextlib.suppress(UnitLinkError):  # gone already (a SIGTERM to the service's every process)
            self.link.send("end")

    def join(self, timeout_s: float) -> list[str]:
        """[] once the unit's process has ended within `timeout_s`, else its name."""
        try:
            self.link.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return [f"unit process of {self.name} (pid {self.link.proc.pid})"]
        return []
