"""The real-time process's command handlers, bound to `orccadd.wire.commands.COMMANDS` by name.

Each handler runs in the automaton thread, gets its arguments already checked against the table
(defaults filled in), and returns a result, a `Pending` result, or raises `CommandError` having
changed nothing.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from orccadd.daemon import adhoc
from orccadd.daemon.loader import Loader
from orccadd.daemon.ports import ResourcePort
from orccadd.daemon.replies import CommandError, Pending, Result
from orccadd.daemon.unitproxy import RemoteLoop
from orccadd.daemon.view import Machine, UnitView
from orccadd.errors import OrccaddError, ParameterError, did_you_mean
from orccadd.runtime.mailbox import MailboxFullError
from orccadd.task import RobotTask
from orccadd.task.task import ParameterChange, split_index
from orccadd.wire.commands import handles
from orccadd.wire.schema import PROTOCOL_VERSION, MachineState, OperatorAction, Trace, TuneRecord

MAX_INJECTED_MS = 5000.0  # longest injected tick: a stall, not a hang
MAX_HANG_MS = 60_000.0  # longest injected hang of a device call
TUNE_WAIT_S = 1.0  # a tune not applied within this (or 100 periods) is reported as such


class RtCommands:
    """The `rt` side of the command table (see `Dispatcher`)."""

    def __init__(self, machine: Machine) -> None:
        self.m = machine
        self.loader = Loader(machine)

    def close(self) -> None:
        """Stop a load's compiler process still running (the daemon is stopping)."""
        self.loader.close()

    def _trace_tune(
        self, t_s: float, task: RobotTask, name: str, change: ParameterChange, old: Any, tick: int
    ) -> None:
        """The operator's tune as the logs tell it: which parameter of which task, which element,
        the values before and after, the tick that applied it (`TuneRecord`)."""
        tid = next(i for i, t in enumerate(self.m.mission.tasks()) if t is task)
        rec = TuneRecord(
            tid, task.tunable_names.index(name), -1 if change.element is None else change.element, tick,
            [float(x) for x in np.atleast_1d(old)], [float(x) for x in np.atleast_1d(change.value)],
        )  # fmt: skip
        head, values = rec.encode()
        self.m.pub.trace(Trace.COMMAND, t_s, OperatorAction.TUNE, inputs=head, actions=values)

    def _trace(self, action: OperatorAction) -> float:
        t = self.m.now_s()
        self.m.pub.trace(Trace.COMMAND, t, action)
        return t

    @handles("describe")
    def describe(self) -> Result:
        return self.m.describe()

    @handles("params")
    def params(self, task: str) -> Result:
        tasks = [self._task(task)] if task else self.m.mission.tasks()
        return {"params": {t.name: t.parameters() for t in tasks}}

    @handles("load")
    def load(self, path: str) -> Result | Pending:
        """Compile and verify in a child process (never in this one: see `Loader`), then build
        the tasks here when it is done: a pending reply meanwhile."""
        return self.loader.load(path)

    @handles("deploy")
    def deploy(
        self, name: str, mission: str, task_files: list[str], task_texts: list[str], by: str
    ) -> Result | Pending:
        """Checked as `load` checks a file, then stored by content (`deploy.py`)."""
        if len(task_files) != len(task_texts):
            raise CommandError(
                f"deploy: {len(task_files)} task file names for {len(task_texts)} texts: one text each"
            )
        return self.loader.deploy(name, mission, dict(zip(task_files, task_texts, strict=True)), by)

    @handles("move")
    def move(
        self, joints_rad: list[float] | None, pose: list[float] | None, resource: str, speed_scale: float
    ) -> Result | Pending:
        """`move`: checked here (`adhoc`), then loaded and started (`_run_adhoc`)."""
        self.loader.check_free("move")
        if (joints_rad is None) == (pose is None):
            raise CommandError("move: give either joints_rad (a joint target) or pose (the tool's)")
        if pose is not None:
            return self._run_adhoc(adhoc.move_pose(self.m, pose, resource, speed_scale))
        assert joints_rad is not None
        return self._run_adhoc(adhoc.move(self.m, joints_rad, resource, speed_scale))

    @handles("jog")
    def jog(self, joint: str, by_rad: float, resource: str, speed_scale: float) -> Result | Pending:
        self.loader.check_free("jog")
        return self._run_adhoc(adhoc.jog(self.m, joint, by_rad, resource, speed_scale))

    @handles("follow")
    def follow(self, csv: str, name: str, resource: str) -> Result | Pending:
        self.loader.check_free("follow")
        return self._run_adhoc(adhoc.follow(self.m, csv, name, resource))

    def _run_adhoc(self, job: adhoc.AdHoc) -> Pending:
        """Load the generated mission as a file's (same compiler, checks, refusals), then start
        it; one reply with both, and what was generated."""
        self._check_no_fault()

        def then(loaded: Result) -> Result:
            started = self.start("")
            return {**started, **job.detail, "report": loaded["report"], "cached": loaded["cached"]}

        return self.loader.load_text(job.text, job.name, job.data, then)

    @handles("start")
    def start(self, procedure: str) -> Result:
        mc = self.m.mission
        mc.need(MachineState.READY, what="start")
        self._check_no_fault()
        t = self._trace(OperatorAction.START)
        main = mc.start(t, procedure)
        assert mc.mission is not None
        return {"started": main, "mission": mc.mission.name, "run": mc.runs}

    def _check_no_fault(self) -> None:
        for u in self.m.units:
            if u.supervisor.fault:
                what = "the arm" if len(self.m.units) == 1 else f"resource {u.name}"
                raise CommandError(f"{what} was safe-stopped ({u.supervisor.fault}): `reset` first")

    @handles("send")
    def send(self, input: str) -> Result:
        mc = self.m.mission
        mc.need(MachineState.RUNNING, MachineState.HOLDING, what="send an input")
        bit = mc.operator_input(input)
        mc.react(self._trace(OperatorAction.SEND), bit)
        return {"sent": input}

    @handles("cell_input")
    def cell_input(self, input: str, peer: str) -> Result:
        """A peer's signal or its loss: one instant with that input, if a run takes it now (a
        mission not running, or not declaring it, lets it go by: the cell's signals are pure
        events, present in one instant or absent)."""
        mc = self.m.mission
        bit = mc.cell_input(input, peer)
        if not bit or mc.state not in (MachineState.RUNNING, MachineState.HOLDING):
            return {"taken": False, "input": input, "peer": peer}
        mc.react(self._trace(OperatorAction.CELL), bit)
        return {"taken": True, "input": input, "peer": peer}

    @handles("stop")
    def stop(self) -> Result:
        """Graceful: the mission's own `Stop` operator input (the procedure's defined stop)."""
        mc = self.m.mission
        mc.need(MachineState.RUNNING, MachineState.HOLDING, what="stop")
        try:
            bit = mc.operator_input("Stop")
        except CommandError as e:
            raise CommandError(f"{e}; the mission defines no graceful stop: use `abort`") from None
        if mc.state is MachineState.HOLDING:
            mc.resume()
        mc.react(self._trace(OperatorAction.STOP), bit)
        return {"stopped": mc.state is not MachineState.RUNNING, "state": mc.state.name.lower()}

    @handles("abort")
    def abort(self) -> Result:
        self._trace(OperatorAction.ABORT)
        self.m.abort("aborted by the operator")
        return {"aborted": True}

    @handles("hold")
    def hold(self) -> Result:
        self.m.mission.hold_mission()
        self._trace(OperatorAction.HOLD)
        return {"holding": True}

    @handles("resume")
    def resume(self) -> Result:
        resumed = self.m.mission.resume()
        self._trace(OperatorAction.RESUME)
        return {"resumed": resumed}

    @handles("reset")
    def reset(self, resource: str) -> Result | Pending:
        def traced() -> None:
            self._trace(OperatorAction.RESET)

        return self._reset(self.m.units if not resource else [self.m.unit(resource)], traced)

    def _reset(self, among: Sequence[UnitView], on_done: Callable[[], None]) -> Result | Pending:
        """The reset of each safe-stopped resource `among` (each refused as it would be alone:
        nothing is reset then); one reply once all are done."""
        units = [u for u in among if u.supervisor.fault or u.resource.stopping_or_stopped]
        if not units:
            return {"reset": False, "detail": "nothing to reset"}
        for u in units:
            u.supervisor.check_reset()
        replies = [u.supervisor.begin_reset(lambda: None) for u in units]
        names = [u.name for u in units]
        done: Result = {"reset": True} if len(self.m.units) == 1 else {"reset": True, "resources": names}
        results: dict[int, Result] = {}

        def poll() -> Result | None:
            for i, r in enumerate(replies):
                if i not in results:
                    got = r.poll() if isinstance(r, Pending) else r
                    if got is not None:
                        results[i] = got
            if len(results) < len(replies):
                return None
            on_done()
            return done

        def expire() -> Result:
            late = [names[i] for i in range(len(replies)) if i not in results]
            raise CommandError(f"the reset of {', '.join(late)} did not end in time")

        deadline = max(
            (r.deadline_ns for r in replies if isinstance(r, Pending)), default=time.monotonic_ns()
        )
        return Pending(poll, deadline, expire)

    def _task(self, name: str) -> RobotTask:
        tasks = self.m.mission.tasks()
        for t in tasks:
            if t.name == name:
                return t
        names = [t.name for t in tasks]
        raise CommandError(f"no task {name!r}{did_you_mean(name, names)} (tasks: {', '.join(names)})")

    @handles("tune")
    def tune(self, path: str, value: Any) -> Result | Pending:
        """Checked here; applied by the control thread at the next tick boundary, whichever task
        it ticks, and acknowledged with that tick's number."""
        parts = path.split(".")
        if len(parts) != 3:
            raise CommandError(f"{path!r}: a parameter is named TASK.MODULE.PARAM (see `params`)")
        task = self._task(parts[0])
        rest = f"{parts[1]}.{parts[2]}"
        try:
            change = task.prepare_tune(rest, value)
        except ParameterError as e:
            raise CommandError(str(e)) from None
        shape = change.param.shape
        if change.element is None and shape and not isinstance(value, list):
            # on a moving arm one number for every joint is a surprise no one wants, gains included
            raise CommandError(
                f"tune {path} (={value!r}): {parts[2]} has {shape[0]} values, one per joint: give "
                f"a list of {shape[0]}, or one joint's as {path}[i] (i from 0)"
            )
        i = change.element
        old = change.param.value.tolist() if i is None else float(change.param.value[i])
        unit = change.param.unit
        on = self.m.unit_of(task)
        loop = on.loop
        try:
            seq = on.post_tune(task, rest, value, change)
        except MailboxFullError as e:
            raise CommandError(f"tune {path}: not accepted: {e}") from None
        self.m.note(f"tune {path} = {value}")
        t_posted = self.m.now_s()

        def poll() -> Result | None:
            tick = on.tune_acked(seq)
            if tick is None:
                return None
            self._trace_tune(t_posted, task, split_index(rest)[0], change, old, tick)
            return {
                "tuned": path,
                "value": value,
                "previous": old,
                "unit": unit,
                "applied_at_tick": tick,
                # set either way; it acts only while the task runs (the next time it does)
                "task_active": loop.active is task,
            }

        def expire() -> Result:
            raise CommandError(
                f"tune {path}: accepted, but the control loop has not applied it (not running?)"
            )

        wait_s = max(100 * on.cfg.control_period_s, TUNE_WAIT_S)
        return Pending(poll, time.monotonic_ns() + int(wait_s * 1e9), expire)

    @handles("inject")
    def inject(self, fault: str, ticks: int, extra_ms: float, resource: str) -> Result:
        """Fault injection for commissioning and tests (only with --allow-fault-injection)."""
        if not self.m.allow_fault_injection:
            raise CommandError("fault injection is disabled (start orccadd with --allow-fault-injection)")
        on = self.m.unit(resource) if resource else self.m.default
        if fault == "resource":
            try:
                on.resource.inject_fault("device", "injected fault")
            except OrccaddError as e:
                raise CommandError(str(e)) from None
        elif fault == "control_thread":
            on.loop.inject_failure()
        elif fault == "unit_process":
            if not isinstance(on.loop, RemoteLoop):
                raise CommandError(
                    f'inject unit_process: {on.name} runs in this process ([daemon] units = "threads")'
                )
            on.loop.inject_crash()
        elif fault == "hang":
            if not 0.0 <= extra_ms <= MAX_HANG_MS:
                raise CommandError(f"inject hang: extra_ms (={extra_ms:g}) must be in [0, {MAX_HANG_MS:g}]")
            on.loop.inject_hang((extra_ms or 1000.0) * 1e-3)
        else:
            if not 0.0 <= extra_ms <= MAX_INJECTED_MS:
                raise CommandError(f"inject: extra_ms (={extra_ms:g}) must be in [0, {MAX_INJECTED_MS:g}]")
            if not 1 <= ticks <= 10_000:
                raise CommandError(f"inject: ticks (={ticks}) must be in [1, 10000]")
            period_ms = on.cfg.control_period_s * 1e3
            on.loop.inject_overrun(ticks, int((extra_ms or 1.5 * period_ms) * 1e6))
        self._trace(OperatorAction.INJECT)
        self.m.note(f"injected fault: {fault} on {on.name}")
        return {"injected": fault, "resource": on.name}


def describe_resource(res: ResourcePort) -> dict[str, Any]:
    return {
        **res.description.as_dict(),
        "tool": describe_tool(res),
        "diagnostics": dataclasses.asdict(res.diagnostics()),
        "protocol_version": PROTOCOL_VERSION,
    }


def describe_tool(res: ResourcePort) -> dict[str, Any]:
    """The tool the Cartesian tasks move ([tool]), its workspace, and where its wrench comes from:
    the resource's sensor (its `wrench` signal) or, without one, an estimate a task makes from the
    joint torques (`wrench_from_torques`)."""
    model = res.model
    frame = model.model.frames[model.tool_frame_id]
    urdf_frame = model.model.frames[frame.parentFrame].name
    sensor = next((g for g in res.description.signals if g.name == "wrench"), None)
    wrench = (
        f"measured: arm.wrench ({sensor.what})"
        if sensor is not None
        else "not measured by this resource: a task estimates it from the joint torques (wrench_from_torques)"
    )
    return {
        **dataclasses.asdict(model.tool),
        "urdf_frame": urdf_frame,
        "workspace": dataclasses.asdict(model.workspace) if model.workspace.given else None,
        "wrench": wrench,
    }
