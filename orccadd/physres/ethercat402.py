"""`ethercat402` backend: an arm of CiA 402 drives on an EtherCAT line (CoE), through SOEM.

The resource maps the Physical Resource contract onto the drives (`drivers.ethercat.master`):

- configure: the line opened and checked, each drive's process data mapped over SDO, the
  distributed clocks, SAFE-OP (`EcatMaster.start`); then the cyclic exchange, OP, and every
  drive walked to SWITCHED ON (powered, torque off, brake on). From there until the control
  loop's first tick a keeper thread runs the exchange every period (a slave in OP without
  outputs for its SM watchdog's time leaves OP, and its drive faults): the first tick takes it
  over for good, so a stalled loop is one the drives notice;
- activate(mode): the mode (0x6060 is in the RxPDO), then Enable Operation from the next ticks,
  holding where the arm is (reads say TORQUE_OFF until every drive is enabled);
- the clock: with distributed clocks the ticks are released at the reference clock's period
  starts (`wait_for_cycle`: each frame brings the reference time back, which maps it onto
  CLOCK_MONOTONIC), SYNC0 coming `sync0_shift_us` later; without, by the loop's own deadlines;
- read: the frame sent at the end of the last tick, back (no waiting: it has had a period):
  positions and velocities as the drives measure them, torques per mille through the gear; a
  drive's FAULT with its error code (0x603F, in the same frame) is FAULT; `lost_frames` frames in
  a row lost or short of the expected working counter is COMM_LOST naming where the line stops;
- write: each drive's outputs (the active mode's target from the command, the others holding)
  and the next frame;
- mode switch: the mode byte of the next frame, within one cycle (CSP and CST both mapped);
- safe_stop: quick stop on every drive (each ramps down at its quick-stop deceleration and
  switches off); STOPPED once every drive is off;
- a slave that leaves OP (its SM watchdog, a cable pulled and put back, its own error) still
  counts in the working counter (SAFE-OP reads and writes the process data) but no longer takes
  its outputs: a thread beside the ticks reads the AL states every 50 ms, and such a slave is
  COMM_LOST naming it and its AL status code;
- reset_fault: slaves that left OP taken back to OP, acknowledging their error; then fault reset
  (rising edge of bit 7) and Enable Operation.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

from orccadd.config.robot import RobotConfig
from orccadd.drivers.canopen import cia402
from orccadd.drivers.canopen.capabilities import object_dictionary
from orccadd.drivers.ethercat.pdo import layout_for
from orccadd.drivers.ethercat.settings import TARGET_OF_MODE, EthercatSettings, load_ethercat_settings
from orccadd.model import RobotModel
from orccadd.physres.cia402_arm import COMMAND_OF, MODE_OF, Cia402Arm, Drive
from orccadd.physres.description import MEASURED, ClockSource, Quantity, ResourceDescription, Source
from orccadd.runtime.clock import WallClock
from orccadd.runtime.rt import ThreadsStartedHere
from orccadd.state import JointState
from orccadd.types import CommandMode

log = logging.getLogger("orccadd.ethercat")

MAILBOX_POLL_S = 0.05
COMMAND_OF_MODE = {"csp": CommandMode.POSITION, "csv": CommandMode.VELOCITY, "cst": CommandMode.TORQUE}


def mapped_modes(s: EthercatSettings) -> frozenset[CommandMode]:
    layouts = [layout_for(object_dictionary(eds, 1)) for eds in s.eds_paths]
    return frozenset(
        COMMAND_OF_MODE[name]
        for name, index in TARGET_OF_MODE.items()
        if all(index in lay.rx for lay in layouts)
    )


class Ethercat402Arm(Cia402Arm):
    Settings = EthercatSettings

    @classmethod
    def claims(cls, config: RobotConfig) -> tuple[str, ...]:
        s: EthercatSettings = config.backend_settings
        return (f"EtherCAT line on {s.interface}",)

    @classmethod
    def describe(cls, config: RobotConfig) -> ResourceDescription:
        """Every mode whose target every drive's RxPDO carries (from their descriptions): with the
        mode of operation in the RxPDO too, the drives switch while enabled, within one cycle."""
        s: EthercatSettings = config.backend_settings
        return ResourceDescription(
            backend="ethercat402",
            joints=config.joint_names,
            modes=mapped_modes(s),
            mode_switch_needs_disable=False,
            position=MEASURED,
            velocity=MEASURED,  # the drive's velocity actual value (0x606C)
            torque=Quantity(Source.ESTIMATED, "the drive's torque actual value 0x6077, from motor current"),
            brakes=True,
            stop_categories=frozenset({0, 1, 2}),
            read_time_s=0.0,  # the frame sent at the end of the last tick is back: no waiting
            write_time_s=0.0,
            # with distributed clocks the reference clock's periods release the ticks
            clock=ClockSource.DEVICE if s.distributed_clocks else ClockSource.LOOP,
            device_period_s=config.control_period_s if s.distributed_clocks else 0.0,
            fault_reset=True,
        )

    @classmethod
    def load_settings(cls, raw: Mapping[str, Any], cfg: RobotConfig, file: str) -> EthercatSettings:
        return load_ethercat_settings(raw, cfg, file)

    def __init__(self, config: RobotConfig, model: RobotModel) -> None:
        super().__init__(config, model)
        from orccadd.drivers.ethercat.master import EcatMaster  # pysoem: the `ethercat` extra

        s: EthercatSettings = config.backend_settings
        self.settings = s
        self.master = EcatMaster(
            s, list(config.joint_names), config.control_period_s, config.safe_stop.deceleration_rad_s2
        )
        self._exchange = threading.RLock()  # one cycle at a time: the keeper's or a tick's
        self._loop_took_over = False
        self._keeper: threading.Thread | None = None
        self._mailbox: threading.Thread | None = None
        self._closing = threading.Event()
        self._sleeper = WallClock()

    @property
    def drives(self) -> Sequence[Drive]:
        return self.master.drives

    @property
    def _walk_timeout_s(self) -> float:
        return self.settings.state_timeout_s

    _walk_timeout_key = "state_timeout_s"

    # ---- lifecycle ------------------------------------------------------------------------
    def _on_configure(self) -> None:
        for w in self.master.start():
            log.warning("%s: %s", self.name, w)
        self.supported_modes = frozenset(COMMAND_OF[m] for m in self.master.modes())
        self._wait(self.master.step_operational, "OP on every slave", every=10)
        self._walk(cia402.State.SWITCHED_ON)
        self._wait(lambda: self._walk_to is None, "SWITCHED ON on every drive")
        self._keeper = threading.Thread(target=self._keep, name=f"{self.name}-ecat-keeper", daemon=True)
        self._mailbox = threading.Thread(
            target=self._watch_mailboxes, name=f"{self.name}-ecat-mailbox", daemon=True
        )
        with ThreadsStartedHere(self.settings.io_priority) as started:
            self._keeper.start()
            self._mailbox.start()
        for w in started.warnings:
            log.warning("%s: %s", self.name, w)

    def _on_activate(self, mode: CommandMode) -> None:
        self.master.set_mode(MODE_OF[mode])
        self._hold_here()
        self._walk(cia402.State.OPERATION_ENABLED)

    def _on_perform_mode_switch(self, mode: CommandMode) -> None:
        self.master.set_mode(MODE_OF[mode])

    def _on_deactivate(self) -> None:
        self._walk_to = None
        self.master.set_controlword(cia402.CW_SHUTDOWN)  # power stage off, still ready
        self._pump(0.1)

    def _on_shutdown(self) -> None:
        self._closing.set()
        for thread in (self._keeper, self._mailbox):
            if thread is not None:
                thread.join(1.0)
        with self._exchange:
            self.master.close()

    def _on_reset_fault(self) -> None:
        """Slaves back to OP where they left it, then fault reset (the next cycles' rising edges)."""
        self._wait(self.master.step_operational, "OP on every slave", every=10)
        self.master.forget_emergencies()
        self._fault_reset = True
        self._walk_failed = ""
        self.fault = None

    # ---- without a loop: the keeper and the blocking phases --------------------------------------
    def _keep(self) -> None:
        """The cyclic exchange from configure until the loop's first tick (see the module's doc)."""
        period = self.config.control_period_s
        while not self._closing.is_set() and not self._loop_took_over:
            if not self.loop_ticking:
                self._cycle_without_loop()
            else:
                time.sleep(period)

    def _watch_mailboxes(self) -> None:
        """A drive's CoE emergency, read from its mailbox once its statusword shows the fault
        (the fault is reported from the process data in that tick; the emergency adds its error
        register to the words), and every slave's AL state (one that left OP is a lost slave)."""
        while not self._closing.wait(MAILBOX_POLL_S):  # SOEM takes frames from two threads
            self.master.read_emergencies()
            self.master.watch_states()

    def _cycle_without_loop(self) -> None:
        with self._exchange:
            if self.master.m is not None:
                now = time.monotonic()
                self._read_into(now, self.state, loop=False)
                self._on_keep_alive(now)
        time.sleep(self.config.control_period_s)

    def wait_for_cycle(self, timeout_s: float) -> int:
        """With distributed clocks: the next period's start on the reference clock (mapped to
        ours by each frame's reference time), or -1 after `timeout_s`."""
        now = time.monotonic_ns()
        due = self.master.next_cycle_ns(now)
        if due - now > timeout_s * 1e9:
            self._sleeper.sleep_until_ns(now + int(timeout_s * 1e9))
            return -1
        self._sleeper.sleep_until_ns(due)
        return due

    # ---- tick hooks ---------------------------------------------------------------------------
    def _read_into(self, t_s: float, state: JointState, loop: bool = True) -> int:
        if loop and not self._loop_took_over:
            self._loop_took_over = True  # the keeper stops: from now on a stalled loop shows
        with self._exchange:
            rep = self.master.receive()
        powered = True
        for j, d in enumerate(self.master.drives):
            state.q_rad[j] = d.position_counts / d.counts_per_rad
            state.dq_rad_s[j] = d.velocity_counts / d.counts_per_rad
            state.tau_nm[j] = d.torque_per_mille * d.nm_per_mille
            powered = powered and d.state in cia402.POWERED
        return self._flags(rep, powered)

    def _send(self, t_s: float) -> None:
        with self._exchange:
            self.master.transmit(self._pos, self._vel, self._tau)

    def _details(self) -> dict[str, Any]:
        m = self.master
        return {
            "interface": self.settings.interface,
            "frames": m.frames,
            "frames_lost": m.frames_lost,
            "wkc_errors": m.wkc_errors,
            "expected_wkc": m.expected_wkc,
            "last_wkc": m.last_wkc,
            "dc_time_ns": m.dc_time_ns,
            **{f"slave_{d.position}": d.identity for d in m.drives},
            **{f"emergency_{d.position}": d.emergency for d in m.drives if d.emergency},
        }
