"""The simulated plant as its own process: a `SimulatedArm` stepping on the wall clock,
talking to the controller through a `PlantChannel`, like a robot's own controller would.

It protects itself like a real arm: once commands stream (the first command after activation
arms the watchdog), no fresh command for `watchdog_periods` periods (the controller stalled or
died) → safe stop; the controller process gone → safe stop, then exit once at rest.

Each step publishes the tool's wrench beside the joint state (the arm's contact world and F/T
sensor: `orccadd.physres.sim_contact`), and what its camera sees if it has one (`features`,
`target_visible`: `orccadd.physres.sim_camera`); the world and the camera's target and occluder
are changed through the plant's control channel (`control.PlantControl`, its port in the
channel's `Ctl.CONTROL_PORT`).
"""

from __future__ import annotations

import contextlib
import os

import numpy as np

from orccadd.config.robot import RobotConfig
from orccadd.model import RobotModel
from orccadd.physres.shm_channel import CAMERA_SIZE, Ctl, PlantChannel, Request
from orccadd.physres.sim import SimulatedArm
from orccadd.physres.sim_contact import WRENCH
from orccadd.plantsim.control import PlantControl
from orccadd.runtime.clock import WallClock
from orccadd.runtime.executor import PeriodicExecutor
from orccadd.runtime.rt import enter_realtime
from orccadd.types import CommandMode, Lifecycle

# A step this many periods after the last one means the process was not running (a VM or
# scheduler stall): the simulated world pauses for the excess instead of integrating the last
# command over it, which no real arm and controller pair would see (the controller, stalled too,
# finds an arm thrown by a stale torque). Counted in `paused_s`.
PAUSE_AFTER_PERIODS = 4


class PlantServer:
    """One plant step per control period: requests → integrate → publish → command."""

    def __init__(
        self, cfg: RobotConfig, channel: PlantChannel, watchdog_periods: int, cycle_fd: int = -1
    ) -> None:
        self.arm = SimulatedArm(cfg, RobotModel.from_config(cfg))
        self.arm.configure()
        self.ch = channel
        self.watchdog_periods = watchdog_periods
        self.cmd = np.zeros(self.arm.dof)
        self.last_seq = -1
        self.stale = 0
        self.streaming = False  # the watchdog arms with the first command after activation
        self.parent = os.getppid()
        self.done = False
        self.watchdog_trips = 0
        self.cycle_fd = cycle_fd  # one byte per step: the controller's loop is paced by it
        self.period_s = cfg.control_period_s
        self.paused_s = 0.0
        self.wrench = self.arm.signals[WRENCH.name]  # the tool's, as the arm's sensor measures it
        self.camera = np.zeros(CAMERA_SIZE) if self.arm.camera is not None else None  # features, visible

    def _handle_request(self) -> None:
        ctl, arm = self.ch.ctl, self.arm
        seq = int(ctl[Ctl.REQ_SEQ])
        if seq == int(ctl[Ctl.ACK_SEQ]):
            return
        code, arg = int(ctl[Ctl.REQ_CODE]), int(ctl[Ctl.REQ_ARG])
        result = 0
        try:
            if code == Request.ACTIVATE:
                ctl[Ctl.STOP] = 0
                arm.activate(CommandMode(arg))
                self.last_seq, self.stale, self.streaming = int(ctl[Ctl.CMD_SEQ]), 0, False
            elif code == Request.SWITCH_MODE:
                arm.switch_mode(CommandMode(arg))
            elif code == Request.DEACTIVATE:
                arm.deactivate()
            elif code == Request.CLEAR_STOP:
                ctl[Ctl.STOP] = 0
                arm.clear_stop()
                self.last_seq, self.stale, self.streaming = int(ctl[Ctl.CMD_SEQ]), 0, False
            elif code == Request.INJECT_FAULT:
                arm.inject_fault("device", "injected fault")
                arm.state.fault_code = arg
            elif code == Request.RESET_FAULT:
                arm.reset_fault()
            elif code == Request.SHUTDOWN:
                arm.shutdown()
                self.done = True
        except Exception:  # reported to the controller as a failed request
            result = 1
        ctl[Ctl.ACK_RESULT] = result
        ctl[Ctl.ACK_SEQ] = seq

    def step(self, t_s: float) -> None:
        ctl, arm = self.ch.ctl, self.arm
        self._handle_request()
        last = arm.t_sim_s
        if last is not None and t_s - last > PAUSE_AFTER_PERIODS * self.period_s:
            self.paused_s += t_s - last - self.period_s
            arm.t_sim_s = t_s - self.period_s  # one period is integrated, the rest was a pause
        st = arm.read(t_s)
        camera = self.camera
        if camera is not None and arm.camera is not None:
            camera[:-1] = arm.camera.features
            camera[-1] = arm.camera.visible[0]
        self.ch.publish_state(t_s, st.q_rad, st.dq_rad_s, st.tau_nm, st.status, self.wrench, camera)
        ctl[Ctl.FAULT_CODE] = st.fault_code
        ctl[Ctl.HEARTBEAT] += 1
        if self.cycle_fd >= 0:
            with contextlib.suppress(BlockingIOError, BrokenPipeError):  # a full pipe: a late reader
                os.write(self.cycle_fd, b"c")
        if arm.lifecycle is not Lifecycle.ACTIVE:
            return
        if ctl[Ctl.STOP]:
            arm.safe_stop()
        seq, mode = self.ch.take_command(self.cmd)
        if seq < 0:  # the controller is mid-write: keep the last command this step
            return
        if seq != self.last_seq:
            self.last_seq, self.stale, self.streaming = seq, 0, True
            if mode == arm.mode:
                arm.write(t_s, self.cmd)
        elif self.streaming:
            self.stale += 1
            if self.stale == self.watchdog_periods and not arm.stopping_or_stopped:
                self.watchdog_trips += 1
                arm.safe_stop()  # the controller is silent: stop like a real arm would
        if os.getppid() != self.parent:
            arm.safe_stop()  # the controller process is gone
            if st.status & 0x20:  # STOPPED
                self.done = True


def plant_main(
    cfg: RobotConfig,
    shm_name: str,
    watchdog_periods: int,
    priority: int,
    cpu: int = -1,
    cycle_fd: int = -1,
    control_port: int = -1,
) -> None:
    """Run the plant until shut down (or its controller is gone and the arm is at rest);
    `control_port` >= 0: its control channel on 127.0.0.1 (0: any free port), -1: none."""
    channel = PlantChannel(cfg.dof, shm_name)
    if cycle_fd >= 0:
        os.set_blocking(cycle_fd, False)
    server = PlantServer(cfg, channel, watchdog_periods, cycle_fd)
    # the control channel's threads start before the priority is raised: time-shared, they never
    # delay a step by more than the interpreter's switch interval
    control = PlantControl(server.arm, control_port) if control_port >= 0 else None
    if control is not None:
        channel.ctl[Ctl.CONTROL_PORT] = control.port
    # its memory locked too: a page fault in a step delays the arm's state by milliseconds, and the
    # controller counts a plant silent for `heartbeat_timeout_periods` as gone (CommLost)
    enter_realtime(priority, cpus={cpu} if cpu >= 0 else None)
    ex = PeriodicExecutor(WallClock(), cfg.control_period_s, server.step)
    try:
        ex.run(until=lambda: server.done)
    finally:
        if control is not None:
            control.close()
        channel.close()


def main() -> int:
    """`python -m orccadd.plantsim --shm NAME ...`, the RobotConfig pickled on stdin
    by the `sim_process` resource that starts it (its own parent: trusted input)."""
    import argparse
    import logging
    import pickle
    import sys

    from orccadd.logsetup import LogSetupError, setup_logging

    ap = argparse.ArgumentParser(prog="python -m orccadd.plantsim", description=main.__doc__)
    ap.add_argument("--shm", required=True)
    ap.add_argument("--watchdog-periods", type=int, required=True)
    ap.add_argument("--priority", type=int, default=0)
    ap.add_argument("--cpu", type=int, default=-1)
    ap.add_argument("--cycle-fd", type=int, default=-1, help="write one byte per step to this fd")
    ap.add_argument(
        "--control-port",
        type=int,
        default=-1,
        help="the control channel (plane, hole, clear_world, occlude, unocclude, target, status) on "
        "127.0.0.1: PORT, 0 any free, -1 none",
    )
    args = ap.parse_args()
    try:
        setup_logging("orccadd.plantsim")
    except LogSetupError as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    cfg = pickle.load(sys.stdin.buffer)
    if not isinstance(cfg, RobotConfig):
        logging.getLogger("orccadd.plantsim").error("stdin is not a RobotConfig")
        return 2
    try:
        plant_main(
            cfg, args.shm, args.watchdog_periods, args.priority, args.cpu, args.cycle_fd, args.control_port
        )
    except OSError as e:  # the control port taken
        logging.getLogger("orccadd.plantsim").error("control port %d: %s", args.control_port, e.strerror)
        return 1
    return 0
