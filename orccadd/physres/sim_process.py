"""`sim_process` backend: the simulated arm runs in its own process (see `orccadd.plantsim`).

The control process then pays only for a shared-memory copy in `read()`/`write()`, as with a
real arm behind a fieldbus. Watchdogs on both sides: the plant stops the arm when commands stop
coming; the controller reports COMM_LOST (type 3) when the plant's heartbeat stops.
"""

from __future__ import annotations

import contextlib
import math
import os
import pickle
import select
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from orccadd.config.robot import RobotConfig
from orccadd.config.schema import field
from orccadd.errors import ResourceError
from orccadd.fault import Fault, FaultKind
from orccadd.model import RobotModel
from orccadd.physres.base import PhysicalResource
from orccadd.physres.description import ClockSource, ResourceDescription
from orccadd.physres.shm_channel import SIGNALS_SIZE, WRENCH_SIZE, Ctl, PlantChannel, Request
from orccadd.physres.sim import INJECTED_FAULT_CODE, SimSettings, load_sim_settings, simulated_description
from orccadd.physres.sim_camera import FEATURES, TARGET_VISIBLE
from orccadd.physres.sim_contact import WRENCH
from orccadd.state import FloatArray, JointState
from orccadd.types import CommandMode, Lifecycle, Status

SELF_STOPPED = int(Status.STOPPING | Status.STOPPED)
# the watchdogs' default tolerance: a development machine's scheduler stalls the real-time threads
# of a busy station for tens of milliseconds now and then (RT throttling fired on our CI VMs; a CI
# run tripped a 40 ms watchdog while a four-resource station held), as ur5e-rtde-sim.toml's 0.5 s
# RTDE watchdog allows for the same reason
WATCHDOG_S = 0.1
WATCHDOG_MIN_PERIODS = 20
KEEPALIVE = 0  # a command "mode" the plant counts as fresh but does not apply


@dataclass(frozen=True)
class SimProcessSettings(SimSettings):
    """`sim` settings plus the process link's watchdogs."""

    # 0: as many periods as `WATCHDOG_S`, at least `WATCHDOG_MIN_PERIODS` (the same tolerance in
    # time whatever the period: a station may run the arm faster than its config does)
    watchdog_periods: int = field(default=0, bounds=(0, 100000))
    heartbeat_timeout_periods: int = field(default=0, bounds=(0, 100000))
    startup_timeout_s: float = field(default=30.0, bounds=(0.1, 600.0))
    plant_priority: int = field(default=70, bounds=(0, 99))
    plant_cpu: int = field(default=-1, bounds=(-1, 1023))  # -1: let the scheduler choose
    # the plant's own cycle paces the control loop, as a UR controller's RTDE stream does
    paced_by_plant: bool = field(default=False)
    # the plant's control channel on 127.0.0.1 (its contact world: docs/simulators.md): this port,
    # 0 any free one (shown as `plant_control` in the resource's details), -1 none
    plant_control_port: int = field(default=0, bounds=(-1, 65535))

    def periods(self, periods: int, period_s: float) -> int:
        """A watchdog's count of periods: `periods`, or its default at `period_s` if 0."""
        if periods:
            return max(2, periods)
        return max(WATCHDOG_MIN_PERIODS, math.ceil(WATCHDOG_S / period_s - 1e-9))


class SimProcessArm(PhysicalResource):
    """A Physical Resource whose plant is a separate process on the same machine."""

    Settings: ClassVar[type[Any]] = SimProcessSettings

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        d = simulated_description("sim_process", config)
        s = config.backend_settings
        if s is not None and s.paced_by_plant:
            d = replace(d, clock=ClockSource.DEVICE, device_period_s=config.control_period_s)
        return d

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        """A fixed port of the plant's control channel is one plant's."""
        s: SimProcessSettings | None = config.backend_settings
        port = s.plant_control_port if s is not None else 0
        return (f"the plant control port 127.0.0.1:{port}",) if port > 0 else ()

    @classmethod
    def load_settings(cls, raw: Any, cfg: RobotConfig, file: str) -> SimProcessSettings:
        """The `sim` checks, with this backend's settings class."""
        return load_sim_settings(SimProcessSettings, raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        s = config.backend_settings
        if s is None:
            s = SimProcessArm.load_settings({}, config, config.source)
        self.settings: SimProcessSettings = s
        self._heartbeat_periods = s.periods(s.heartbeat_timeout_periods, config.control_period_s)
        self.channel: PlantChannel | None = None
        self.process: Any = None
        self._buf = np.zeros(1 + 3 * self.dof + SIGNALS_SIZE)
        self._wrench = self.signals[WRENCH.name]
        self._features = self.signals.get(FEATURES.name)  # None: the arm has no camera
        self._visible = self.signals.get(TARGET_VISIBLE.name)
        self._last_heartbeat = -1
        self._silent_reads = 0
        self._last_cmd: FloatArray = np.zeros(self.dof)
        self._cycle_r = -1  # the plant's cycle pipe (paced_by_plant)
        self.cycles_dropped = 0
        self._settled_heartbeat = 0
        # a dead plant's channel and cycle pipe, kept open until shutdown: the control thread may
        # still hold them in the tick during which a reset swaps in the new plant's
        self._retired: list[tuple[PlantChannel, int]] = []
        self.plant_starts = 0

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        s = self.settings
        self.channel = PlantChannel(self.dof, create=True)
        try:
            self._start_plant(s)
        except BaseException:
            self._release()
            raise

    def _start_plant(
        self, s: SimProcessSettings, config: RobotConfig | None = None, channel: PlantChannel | None = None
    ) -> None:
        """Start the plant process on `channel` (default: ours) with `config` (default: ours),
        wait for its first heartbeat."""
        channel = channel or self.channel
        assert channel is not None
        self.plant_starts += 1
        cmd = [
            sys.executable,
            "-m",
            "orccadd.plantsim",
            "--shm",
            channel.name,
            "--watchdog-periods",
            str(s.periods(s.watchdog_periods, self.config.control_period_s)),
            "--priority",
            str(s.plant_priority),
            "--control-port",
            str(s.plant_control_port),
        ]
        pass_fds: tuple[int, ...] = ()
        if s.paced_by_plant:
            self._cycle_r, cycle_w = os.pipe2(os.O_CLOEXEC | os.O_NONBLOCK)
            cmd += ["--cycle-fd", str(cycle_w)]
            pass_fds = (cycle_w,)
        try:
            # its own process group: a signal to the controller's group (Ctrl-C, `kill %1`, systemd)
            # must reach the controller alone, which stops the arm before it ends the plant
            self.process = subprocess.Popen(
                cmd, stdin=subprocess.PIPE, pass_fds=pass_fds, start_new_session=True
            )
        finally:
            for fd in pass_fds:
                os.close(fd)
        assert self.process.stdin is not None
        self.process.stdin.write(pickle.dumps(config or self.config))
        self.process.stdin.close()
        deadline = time.monotonic() + s.startup_timeout_s
        while channel.ctl[Ctl.HEARTBEAT] == 0:
            if not self.plant_alive():
                code = self.process.returncode
                raise ResourceError(f"resource {self.name!r}: the plant process exited (code {code})")
            if time.monotonic() > deadline:
                self.process.kill()
                raise ResourceError(
                    f"resource {self.name!r}: the plant process did not start "
                    f"within {s.startup_timeout_s:g} s"
                )
            time.sleep(0.01)

    def _request(self, code: Request, arg: int = 0, timeout_s: float = 2.0) -> None:
        ch = self._ch()
        ctl = ch.ctl
        ctl[Ctl.REQ_CODE] = code
        ctl[Ctl.REQ_ARG] = arg
        seq = int(ctl[Ctl.REQ_SEQ]) + 1
        ctl[Ctl.REQ_SEQ] = seq
        deadline = time.monotonic() + timeout_s
        while int(ctl[Ctl.ACK_SEQ]) != seq:
            if time.monotonic() > deadline or not self.plant_alive():
                raise ResourceError(
                    f"resource {self.name!r}: the plant did not acknowledge "
                    f"{code.name.lower()} within {timeout_s:g} s"
                )
            time.sleep(0.0005)
        if ctl[Ctl.ACK_RESULT]:
            raise ResourceError(f"resource {self.name!r}: the plant refused {code.name.lower()}")

    def _ch(self) -> PlantChannel:
        if self.channel is None:
            raise ResourceError(f"resource {self.name!r} is not configured")
        return self.channel

    def _on_activate(self, mode: CommandMode) -> None:
        self._request(Request.ACTIVATE, int(mode))
        self._ch().read_state(self._buf)
        n = self.dof
        self.state.q_rad[:] = self._buf[1 : 1 + n]
        self._wrote = True

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        self._request(Request.SWITCH_MODE, int(mode))

    def _on_deactivate(self) -> None:
        if self.plant_alive():  # a dead plant has nothing left to disable
            self._request(Request.DEACTIVATE)

    def _on_clear_stop(self) -> None:
        self._request(Request.CLEAR_STOP)
        # the plant acknowledges before it publishes its next state: until then the state it
        # last published still says "stopped", which must not read as a stop of its own
        self._settled_heartbeat = int(self._ch().ctl[Ctl.HEARTBEAT]) + 1

    def _on_inject_fault(self, kind: str, message: str) -> None:
        """Make the plant report a device fault (tests). Not for a tick."""
        self.fault = Fault(FaultKind.DEVICE, self.name, message, code=INJECTED_FAULT_CODE)
        self._request(Request.INJECT_FAULT, INJECTED_FAULT_CODE)

    def _on_reset_fault(self) -> None:
        if not self.plant_alive():
            self._respawn()
        else:
            self._request(Request.RESET_FAULT)
        self.fault = None

    def _respawn(self) -> None:
        """A new plant process in place of a dead one (a reset after it was killed): at rest where
        the arm was last measured, active in the current mode, on a fresh channel. As a drive's
        power cycled: the reset's own reads then show whether it answers. Not for a tick."""
        s = self.settings
        start = replace(s, initial_q_rad=tuple(self.state.q_rad.tolist()))
        old = self.channel
        self.channel = None  # the ticks meanwhile read COMM_LOST and send nothing
        if old is not None:
            self._retired.append((old, self._cycle_r))
            old.shm.unlink()  # its name goes now; its memory when nothing maps it (shutdown)
            self._cycle_r = -1
        channel = PlantChannel(self.dof, create=True)
        try:
            self._start_plant(start, replace(self.config, backend_settings=start), channel)
        except BaseException:
            channel.close(unlink=True)
            raise
        self._last_heartbeat, self._silent_reads, self._settled_heartbeat = -1, 0, 0
        self.channel = channel  # publishing the state of an arm at rest where ours was
        self._request(Request.ACTIVATE, int(self.mode))

    def helper_pid(self) -> int:
        return int(self.process.pid) if self.plant_alive() else 0

    def _details(self) -> dict[str, float | int | str]:
        ch = self.channel
        return {
            **super()._details(),
            "plant_channel": ch.name if ch is not None else "",
            "plant_control": self.plant_control,
            "cycles_dropped": self.cycles_dropped,
            "plant_starts": self.plant_starts,
        }

    @property
    def plant_control(self) -> str:
        """The plant's control channel (`python -m orccadd.simctl ADDRESS ...`), "" if none."""
        ch = self.channel
        port = int(ch.ctl[Ctl.CONTROL_PORT]) if ch is not None else 0
        return f"127.0.0.1:{port}" if port else ""

    def plant_alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def _on_shutdown(self) -> None:
        if self.plant_alive():
            with contextlib.suppress(ResourceError):
                self._request(Request.SHUTDOWN, timeout_s=2.0)
            try:
                self.process.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=2.0)
        self._release()

    def _release(self) -> None:
        if self._cycle_r >= 0:
            os.close(self._cycle_r)
            self._cycle_r = -1
        if self.channel is not None:
            self.channel.close(unlink=True)
            self.channel = None
        for channel, cycle_r in self._retired:
            channel.close()
            if cycle_r >= 0:
                os.close(cycle_r)
        self._retired.clear()

    # ---- tick -----------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState) -> int:
        ch = self.channel
        if ch is None:
            return int(Status.COMM_LOST)
        status = ch.read_state(self._buf)
        if status < 0:  # the plant is mid-write: keep the previous measurement this tick
            return int(ch.ctl[Ctl.STATUS]) & int(Status.FAULT)
        n3 = 1 + 3 * self.dof
        state.vector[:] = self._buf[1:n3]  # q, dq, tau
        self._wrench[:] = self._buf[n3 : n3 + WRENCH_SIZE]
        if self._features is not None and self._visible is not None:  # the camera's
            self._features[:] = self._buf[n3 + WRENCH_SIZE : -1]
            self._visible[0] = self._buf[-1]
        state.fault_code = int(ch.ctl[Ctl.FAULT_CODE])
        hb = int(ch.ctl[Ctl.HEARTBEAT])
        if hb == self._last_heartbeat:
            self._silent_reads += 1
        else:
            self._last_heartbeat, self._silent_reads = hb, 0
        flags = status & ~SELF_STOPPED & ~int(Status.LIMIT_VIOLATION)
        if self._silent_reads >= self._heartbeat_periods:
            flags |= Status.COMM_LOST
            if self.plant_alive():
                self._set_fault(FaultKind.COMM_LOST, "the plant process stopped answering")
            else:  # gone: nothing is left to move or to stop (`reset` starts a new one)
                code = self.process.returncode
                self._set_fault(
                    FaultKind.COMM_LOST, f"the plant process stopped answering: it exited (code {code})"
                )
                if self._stop_flags & Status.STOPPING:
                    self._mark_stopped(torque_off=True)
        # a state published before a cleared stop was confirmed still says "stopped": not news
        if status & SELF_STOPPED and hb >= self._settled_heartbeat:
            if not self._stop_flags:  # the arm stopped by itself (its watchdog): fatal here
                flags |= Status.FAULT
                self._set_fault(FaultKind.DEVICE, "the arm stopped on its own (command watchdog)")
            elif status & Status.STOPPED:
                self._mark_stopped(bool(status & Status.TORQUE_OFF))
        return flags

    def _on_keep_alive(self, t_s: float) -> None:
        ch = self.channel
        if ch is not None and self.lifecycle is Lifecycle.ACTIVE and not self._stop_flags:
            ch.send_command(KEEPALIVE, self._last_cmd)  # no new command: the plant holds its last

    def wait_for_cycle(self, timeout_s: float) -> int:
        """The plant's next step (paced_by_plant): its arrival time, or -1 after `timeout_s`."""
        if self._cycle_r < 0:
            if not self.settings.paced_by_plant:
                return super().wait_for_cycle(timeout_s)
            time.sleep(max(0.0, timeout_s))  # a new plant is being started (reset): no cycle
            return -1
        ready, _, _ = select.select([self._cycle_r], [], [], max(0.0, timeout_s))
        if not ready:
            return -1
        arrived = time.monotonic_ns()
        with contextlib.suppress(BlockingIOError):
            self.cycles_dropped += max(0, len(os.read(self._cycle_r, 4096)) - 1)
        return arrived

    def _write_command(self, t_s: float, mode: CommandMode, command: FloatArray) -> int:
        ch = self.channel
        if ch is None:
            return int(Status.COMM_LOST)
        ch.send_command(int(mode), command)
        self._last_cmd[:] = command
        return 0

    def _begin_safe_stop(self) -> None:
        if self.channel is not None:
            self.channel.ctl[Ctl.STOP] = 1
