"""One simulated CiA 402 drive: a `SlaveNode` for the bus, a `DriveStateMachine`, and joint `j`
of the shared `DriveTrainArm`.

Units as on a real drive: positions in encoder increments, velocities in increments per
second, torques in thousandths of the rated torque (0x6076, motor side), through the gear:

    increments = rad × counts_per_rev × gear_ratio / 2π
    per mille  = τ_joint / (gear_ratio × rated_torque_nm) × 1000

The drive runs in the mode its display shows (0x6061). A mode written to 0x6060 is shown at
once, before the write is confirmed (a real drive takes it within its own cycle, before it
answers), or `Strictness.mode_display_delay_s` later for a drive made to lag; a mode its
supported drive modes (0x6502) do not list is refused, SDO abort 0x06090030, and 0x6061 stays
(`Strictness.supported_modes`; an RPDO's refused mode is ignored). Every SYNC (`cycle`): in
OPERATION ENABLED the target of the mode (CSP 0x607A, CSV 0x60FF, CST 0x6071, plus the torque
offset 0x60B2 if mapped) becomes the joint's reference; a quick stop or a fault reaction ramps
the joint down at the quick-stop deceleration (0x6085) and then switches the power stage off;
a CSP following error beyond the window (0x6065) for its time-out (0x6066) is a fault (EMCY
0x8611). Actual values (0x6064, 0x606C, 0x6077) and the statusword are refreshed before the
TPDOs go out. A drive that watches a heartbeat (0x1016) and loses it faults with EMCY 0x8130
(`Strictness.heartbeat_consumer`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from orccadd.drivers.canopen.cia402 import (
    MODE_CSP,
    MODE_CST,
    MODE_CSV,
    SW_FOLLOWING,
    SW_FOLLOWING_ERROR,
    SW_TARGET_REACHED,
    SW_WARNING,
    DriveStateMachine,
    State,
)
from orccadd.drivesim.plant import Drive, DriveTrainArm
from orccadd.drivesim.slave import ABORT_VALUE_RANGE, SdoAbortError, SlaveNode

# EMCY error codes (CiA 301 / CiA 402)
EMCY_OVERCURRENT = 0x2310
EMCY_FOLLOWING_ERROR = 0x8611
EMCY_HEARTBEAT = 0x8130
EMCY_RESET = 0x0000
ERR_REG_GENERIC, ERR_REG_CURRENT, ERR_REG_COMM, ERR_REG_MANUFACTURER = 0x01, 0x02, 0x10, 0x80

NEVER = math.inf  # a mode display delay: the drive never shows the mode asked
STOP_SPEED_RAD_S = 0.01
STOP_TIMEOUT_S = 1.0  # after the ramp, longest wait for standstill before the brake


CW_ENABLE_OPERATION_BIT = 0x08
PUBLISH_EVERY_S = 0.001  # the drive's own cycle refreshes its statusword and actual values


@dataclass(frozen=True)
class Strictness:
    """Behaviours of real drives that a lenient simulation would let a master get away with. All
    on by default, so the master is tested against them; each can be relaxed for a test that
    needs the lenient drive."""

    heartbeat_consumer: bool = True  # a heartbeat watched (0x1016) and lost: FAULT, EMCY 0x8130
    cob_id_valid_bit: bool = True  # a valid COB-ID's identifier cannot change: abort 0x06090030
    supported_modes: bool = True  # a mode 0x6502 does not list: abort 0x06090030, 0x6061 unchanged
    # 0x6061 shows a new 0x6060 this much later (0: at once, before the write is confirmed; NEVER:
    # never), for a master's test against a drive that lags
    mode_display_delay_s: float = 0.0


STRICT = Strictness()


@dataclass(frozen=True)
class AxisUnits:
    counts_per_rev: int
    gear_ratio: float
    rated_torque_nm: float  # motor side

    @property
    def counts_per_rad(self) -> float:
        return self.counts_per_rev * self.gear_ratio / (2 * math.pi)

    @property
    def nm_per_mille(self) -> float:  # joint N·m per thousandth of rated torque
        return self.gear_ratio * self.rated_torque_nm / 1000.0


class Axis:
    def __init__(
        self, node: SlaveNode, joint: int, arm: DriveTrainArm, units: AxisUnits, strict: Strictness = STRICT
    ) -> None:
        self.node = node
        self.strict = strict
        self.j = joint
        self.arm = arm
        self.units = units
        self.sm = DriveStateMachine(self._get(0x605A, 2))
        self.fault_code = 0
        self._following_since: float | None = None
        self._stop_v0 = 0.0
        self._stop_t0 = 0.0
        self._prev_target: float | None = None
        self._limits: dict[tuple[int, int], tuple[int, int]] = {}
        self._mode_due: tuple[int, float] | None = None  # (mode asked, when the display shows it)
        self._published_s = -1.0  # when the statusword and actual values were last refreshed
        self.sto = False  # Safe Torque Off active: the power stage cannot be enabled
        node.on_write[(0x6040, 0)] = self._controlword
        node.on_write[(0x6060, 0)] = self._mode_asked
        node.checks[(0x6060, 0)] = self._check_mode
        node.on_reset_node = self.reset
        if strict.heartbeat_consumer:
            node.on_heartbeat_lost = lambda producer: self.fault(EMCY_HEARTBEAT, ERR_REG_COMM)

    # ---- object access with defaults for objects a description may lack -----------------------
    def _get(self, index: int, default: int, sub: int = 0) -> int:
        value = self.node.values.get((index, sub))
        return default if value is None else int(value)

    def _set(self, index: int, value: int, sub: int = 0) -> None:
        """Store a value the drive produces, saturated to the object's data type (if it has it)."""
        key = (index, sub)
        limits = self._limits.get(key)
        if limits is None:
            if not self.node.has(index, sub):
                return
            limits = self._limits[key] = _range(self.node.vars[key].data_type)
        lo, hi = limits
        self.node.values[key] = lo if value < lo else hi if value > hi else value

    # ---- state machine -------------------------------------------------------------------------
    def boot(self) -> None:
        self.sm = DriveStateMachine(self._get(0x605A, 2))
        self.sm.boot()
        self._mode_due = None
        self._set(0x6061, self._get(0x6060, 0))  # powered up in the mode of 0x6060
        self._publish()

    def reset(self) -> None:
        """NMT reset node: the drive restarts (power stage off, fault cleared, self-test done),
        its dictionary back to its defaults: SWITCH ON DISABLED, in the mode of 0x6060, as at
        power-on."""
        self.arm.drive[self.j] = Drive.OFF
        self.fault_code = 0
        self.boot()

    def _controlword(self, cw: int) -> None:
        before = self.sm.state
        if self.sto:  # Enable Operation refused (transition 4): at most SWITCHED ON
            cw = int(cw) & ~CW_ENABLE_OPERATION_BIT
        t = self.sm.controlword(int(cw))
        if t == 15:  # fault reset: the error is acknowledged
            self.fault_code = 0
            self.node.emergency(EMCY_RESET, 0)
        if (
            t is not None
            and self.sm.state is State.OPERATION_ENABLED
            and before is not State.OPERATION_ENABLED
        ):
            self._enable()
        if t == 11:
            self._begin_stop()

    def fault_text(self) -> str:
        """The drive's fault as a status reply says it: its error code, an injected silence, STO."""
        parts = [f"error 0x{self.fault_code:04X}"] if self.fault_code else []
        if self.node.silent:
            parts.append("node silent")
        elif self.node.heartbeat_silent:
            parts.append("heartbeat silent")
        if self.sto:
            parts.append("Safe Torque Off")
        return ", ".join(parts)

    def fault(self, code: int, register: int = ERR_REG_GENERIC) -> None:
        """A drive fault: EMCY, then the fault reaction (a controlled stop), then FAULT."""
        if self.sm.fault() is None:
            return
        self.fault_code = code
        self._set(0x603F, code)
        self.node.emergency(code, register | ERR_REG_GENERIC)
        self._begin_stop()

    def _enable(self) -> None:
        """Power stage on: hold where the joint is until the first target arrives."""
        self.arm.position_ref[self.j] = self.arm.q[self.j]
        self.arm.velocity_ref[self.j] = 0.0
        self._prev_target = None
        if self._mode() == MODE_CSP:
            self._set(0x607A, round(self.arm.q[self.j] * self.units.counts_per_rad))

    def _begin_stop(self) -> None:
        self._stop_v0 = float(self.arm.dq[self.j])
        self._stop_t0 = float(self.arm.t_sim_s or 0.0)

    def _check_mode(self, mode: int) -> None:
        """A mode of operation asked (0x6060), before it is stored: refused (SDO abort 0x06090030,
        value range exceeded) unless the drive's supported drive modes (0x6502) list it."""
        if self.strict.supported_modes and not supports_mode(self._get(0x6502, 0), int(mode)):
            raise SdoAbortError(ABORT_VALUE_RANGE)

    def _mode_asked(self, mode: int) -> None:
        """A mode of operation taken (0x6060 stored): shown (0x6061) and run at once, within the
        handling of the write that brought it (before an SDO write's confirmation goes out), or
        `mode_display_delay_s` later."""
        if self.strict.mode_display_delay_s <= 0:
            self._mode_due = None
            self._set(0x6061, int(mode))
            return
        self._mode_due = (int(mode), self.node.now_s + self.strict.mode_display_delay_s)
        self.poll(self.node.now_s)

    def poll(self, now_s: float) -> None:
        """The drive's own cycle between SYNCs (a real drive runs it whatever the bus does): the
        mode display catches up with a mode asked, the statusword and actual values are fresh
        for an SDO read."""
        due = self._mode_due
        if due is not None and now_s >= due[1]:
            self._mode_due = None
            self._set(0x6061, due[0])
        if now_s - self._published_s >= PUBLISH_EVERY_S:  # SYNCs publish too: no need then
            self._publish()

    def _mode(self) -> int:
        """The mode the drive runs in: the one it shows (0x6061)."""
        return self._get(0x6061, 0)

    # ---- the drive's cycle, once per SYNC --------------------------------------------------------
    def cycle(self, now_s: float, period_s: float) -> None:
        arm, j, sm = self.arm, self.j, self.sm
        self.poll(now_s)
        mode = self._mode()
        st = sm.state
        if st is State.OPERATION_ENABLED and mode in (MODE_CSP, MODE_CSV, MODE_CST):
            self._follow(mode, now_s, period_s)
        elif st in (State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE):
            if self._ramp_down():
                arm.drive[j] = Drive.OFF
                if st is State.QUICK_STOP_ACTIVE:
                    if sm.quick_stop_done() is None:  # options 5-8: stay, holding position
                        arm.drive[j] = Drive.POSITION
                        arm.position_ref[j] = arm.q[j]
                        arm.velocity_ref[j] = 0.0
                else:
                    sm.fault_reaction_done()
        elif st is State.OPERATION_ENABLED:
            arm.drive[j] = Drive.POSITION  # a mode this simulation does not run: hold
        else:
            arm.drive[j] = Drive.OFF
        self._publish()

    def _follow(self, mode: int, now_s: float, period_s: float) -> None:
        arm, j, u = self.arm, self.j, self.units
        if mode == MODE_CST:
            offset = self._get(0x60B2, 0)
            arm.drive[j] = Drive.TORQUE
            arm.torque_ref[j] = (self._get(0x6071, 0) + offset) * u.nm_per_mille
        elif mode == MODE_CSV:
            arm.drive[j] = Drive.VELOCITY
            arm.velocity_ref[j] = self._get(0x60FF, 0) / u.counts_per_rad
        else:
            target = self._get(0x607A, 0) / u.counts_per_rad
            prev = self._prev_target if self._prev_target is not None else target
            arm.drive[j] = Drive.POSITION
            arm.position_ref[j] = target
            arm.velocity_ref[j] = (target - prev) / self.interpolation_period_s(period_s)
            self._prev_target = target
            self._check_following(now_s)

    def interpolation_period_s(self, default_s: float) -> float:
        """The time between two position targets, as configured (0x60C2, else the communication
        cycle 0x1006), as a real drive has it: never the measured spacing of SYNCs, which a
        delayed bus delivers in bursts (two SYNCs 0.1 ms apart made the velocity feed-forward
        20 times too large)."""
        value = self._get(0x60C2, 0, 1)
        if value > 0:
            return value * 10.0 ** self._get(0x60C2, -3, 2)
        cycle_us = self._get(0x1006, 0)
        return cycle_us * 1e-6 if cycle_us > 0 else default_s

    def _check_following(self, now_s: float) -> None:
        window = self._get(0x6065, 0)
        if not window or window == 0xFFFFFFFF:
            return
        err = abs(self.arm.position_ref[self.j] - self.arm.q[self.j]) * self.units.counts_per_rad
        if err <= window:
            self._following_since = None
            return
        if self._following_since is None:
            self._following_since = now_s
        if (now_s - self._following_since) * 1000 >= self._get(0x6066, 0):
            self._following_since = None
            self.fault(EMCY_FOLLOWING_ERROR)

    def _ramp_down(self) -> bool:
        """Velocity ramp to standstill at the quick stop deceleration; True once stopped."""
        arm, j = self.arm, self.j
        decel = self._get(0x6085, 0) / self.units.counts_per_rad or 10.0  # rad/s²
        elapsed = float(arm.t_sim_s or 0.0) - self._stop_t0
        v = max(abs(self._stop_v0) - decel * elapsed, 0.0)
        arm.drive[j] = Drive.VELOCITY
        arm.velocity_ref[j] = math.copysign(v, self._stop_v0)
        settled = v == 0.0 and abs(arm.dq[j]) < STOP_SPEED_RAD_S
        return settled or elapsed > abs(self._stop_v0) / decel + STOP_TIMEOUT_S  # then brake anyway

    def _publish(self) -> None:
        self._published_s = self.node.now_s
        arm, j, u = self.arm, self.j, self.units
        self._set(0x6064, round(arm.q[j] * u.counts_per_rad))
        self._set(0x606C, round(arm.dq[j] * u.counts_per_rad))
        self._set(0x6077, round(arm.tau_applied[j] / u.nm_per_mille))
        sw = self.sm.statusword
        if self.sm.state is State.OPERATION_ENABLED and self._mode() in (MODE_CSP, MODE_CSV, MODE_CST):
            sw |= SW_FOLLOWING
            if self._following_since is not None:
                sw |= SW_FOLLOWING_ERROR | SW_WARNING
        if abs(arm.dq[j]) < STOP_SPEED_RAD_S:
            sw |= SW_TARGET_REACHED
        self._set(0x6041, sw)


def supports_mode(supported: int, mode: int) -> bool:
    """Whether supported drive modes `supported` (0x6502) list mode of operation `mode` (0x6060):
    CiA 402 gives mode m = 1..16 bit m - 1 (1 pp, 2 vl, 3 pv, 4 tq, 6 hm, 7 ip, 8 csp, 9 csv,
    10 cst) and bits 16-31 to the manufacturer, read here as modes -1..-16. Mode 0 (no mode
    assigned) is always taken; so is every mode where 0x6502 is 0 (a description that leaves it
    empty says nothing)."""
    if supported == 0 or mode == 0:
        return True
    bit = mode - 1 if mode > 0 else 15 - mode
    return 0 <= bit < 32 and bool(supported >> bit & 1)


def _range(data_type: int | None) -> tuple[int, int]:
    bits = {2: 8, 3: 16, 4: 32, 5: 8, 6: 16, 7: 32, 0x15: 64, 0x1B: 64}.get(data_type or 0, 32)
    signed = data_type in (2, 3, 4, 0x15)
    return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
