"""The chain: servos on one bus, moving one arm. Instruction packets in, status packets out.

`handle(packet, now_s)` is the servos' side of one instruction (e-Manual, Protocol 2.0,
Instruction Details): who executes it (the ID, the Secondary ID without a reply, every servo on
Broadcast ID 0xFE), who answers and in which order (Status Return Level(68): 0 ping only, 1
ping and reads, 2 all; no answer to a broadcast except ping and the sync/bulk reads), and what
the answers are. It returns the status packets in bus order, each with the return delay its
servo waits after the bus went quiet; the link turns that into wire time.

`advance_to(now_s)` integrates the arm in `SERVO_PERIOD_S` steps, each servo's control loop
giving its joint's torque. Faults are injected with `inject`.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np

from orccadd.config.robot import RobotConfig
from orccadd.dxlsim import table as T
from orccadd.dxlsim.models import MODELS
from orccadd.dxlsim.protocol import (
    BROADCAST_ID,
    Error,
    Instruction,
    Packet,
    fast_status_packet,
    status_packet,
)
from orccadd.dxlsim.servo import OVERHEATING, OVERLOAD, RESET_ALL, Servo
from orccadd.dxlsim.settings import ChainSettings
from orccadd.model import RobotModel
from orccadd.physres.arm_dynamics import ArmDynamics

SERVO_PERIOD_S = 0.001  # the servos' control period and the arm's integration step
INERTIA_EVERY = 10  # steps between two looks at the arm's inertia (it changes slowly with the pose)
VISCOUS_NM_S_RAD = 0.01
FAULTS = ("overload", "overheating", "unplug", "replug", "noise", "late", "object", "remove_object", "clear")
READS = (Instruction.READ, Instruction.SYNC_READ, Instruction.BULK_READ)
FAST_READS = (Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ)
FAST_READ_FIRMWARE = 45  # X-series firmware with Fast Sync/Bulk Read (ROBOTIS e-Manual)


@dataclass(frozen=True)
class Reply:
    """A status packet and the return delay its sender waits once the bus is free."""

    data: bytes
    delay_s: float


def _word(b: bytes, i: int) -> int:
    return b[i] | b[i + 1] << 8


@dataclass(frozen=True)
class Obstacle:
    """Something a joint meets (an object between a gripper's fingers, a workpiece): beyond
    `at_rad` in its `closing` sense (+1: growing angles) the joint is pushed back by a spring of
    `stiffness_nm_rad` with a little damping, as a compliant object pushes back on the fingers."""

    joint: int
    at_rad: float
    stiffness_nm_rad: float
    closing: int
    damping_nm_s_rad: float = 0.2

    def torque_nm(self, q_rad: float, dq_rad_s: float) -> float:
        depth = self.closing * (q_rad - self.at_rad)
        if depth <= 0.0:
            return 0.0
        push = self.stiffness_nm_rad * depth + self.damping_nm_s_rad * self.closing * dq_rad_s
        return -self.closing * max(0.0, push)


class Chain:
    def __init__(
        self,
        cfg: RobotConfig,
        settings: ChainSettings,
        q0_rad: list[float] | None = None,
        firmware: dict[int, int] | None = None,
    ) -> None:
        """`firmware`: servo id → its Firmware Version, where not the model's (an older one)."""
        self.settings = settings
        self.baud = settings.baud_rate
        baud_index = T.BAUD_RATES_BIT_S.index(self.baud)
        self.servos = [Servo(MODELS[s.model], s.id, baud_index) for s in settings.servos]
        for servo in self.servos:
            if firmware and servo.dxl_id in firmware:
                servo.table.set(T.FIRMWARE_VERSION, firmware[servo.dxl_id])
        # horn angle = k · (q - offset), joint torque = k · horn torque
        self._k = [s.direction * s.gear_ratio for s in settings.servos]
        self._offset = [s.offset_rad for s in settings.servos]
        models = [MODELS[s.model] for s in settings.servos]
        gear = np.array([s.gear_ratio for s in settings.servos])
        reflected = np.array([m.rotor_inertia_kg_m2 for m in models]) * gear**2
        friction = np.array([m.friction_nm for m in models]) * gear
        model = RobotModel.from_config(cfg)
        q0 = np.array(q0_rad if q0_rad is not None else model.home_rad, dtype=np.float64)
        self.arm = ArmDynamics(
            model,
            q0,
            viscous_nm_s_rad=np.full(len(models), VISCOUS_NM_S_RAD),
            coulomb_nm=friction,
            armature_kg_m2=reflected,
            hard_stops=True,
        )
        self._tau_nm = np.zeros(len(models))
        self.obstacles: dict[int, Obstacle] = {}  # by joint
        self.t_s: float | None = None
        self.last_packet_s = 0.0
        self.noise_rate = 0.0
        self.late_s = 0.0  # the next `late_packets` status packets come this much later
        self.late_packets = 0
        self.rng = random.Random(1)
        self.packets = 0
        self.crc_errors = 0

    # ---- time -----------------------------------------------------------------------------
    def start(self, now_s: float) -> None:
        self.t_s = self.last_packet_s = now_s
        self._sample()
        for servo in self.servos:
            servo.boot(now_s)
            servo.awake_at_s = now_s  # powered before the controller came

    def advance_to(self, now_s: float, max_catch_up_s: float = math.inf) -> None:
        """Run the servos and the arm up to `now_s` (simulator clock, seconds); a gap longer than
        `max_catch_up_s` (the process was stopped) is skipped, not integrated."""
        assert self.t_s is not None, "start() first"
        if now_s - self.t_s > max_catch_up_s:
            self.t_s = now_s - max_catch_up_s
        h = SERVO_PERIOD_S
        k, offset, servos = self._k, self._offset, self.servos
        arm, tau = self.arm, self._tau_nm
        steps = 0
        while self.t_s + h <= now_s:
            if steps % INERTIA_EVERY == 0:  # the inertia changes slowly with the pose
                arm.refresh_inertia()
            q, dq = arm.q.tolist(), arm.dq.tolist()
            idle = self.t_s - self.last_packet_s
            for j, servo in enumerate(servos):
                tau[j] = k[j] * servo.step(k[j] * (q[j] - offset[j]), k[j] * dq[j], h, idle)
            for j, obstacle in self.obstacles.items():
                tau[j] += obstacle.torque_nm(q[j], dq[j])
            arm.step(tau, h)
            self.t_s += h
            steps += 1

    def _sample(self) -> None:
        """Give every servo its horn's angle and speed (before a read, at start)."""
        q, dq = self.arm.q.tolist(), self.arm.dq.tolist()
        for j, servo in enumerate(self.servos):
            k = self._k[j]
            servo.loop.theta_rad, servo.loop.omega_rad_s = k * (q[j] - self._offset[j]), k * dq[j]

    # ---- the bus --------------------------------------------------------------------------
    def handle(self, packet: Packet, now_s: float) -> list[Reply]:
        """Execute one instruction packet at `now_s`; the status packets it earns, in bus order."""
        self.advance_to(now_s)
        self.packets += 1
        listening = [s for s in self.servos if s.hears(self.baud, now_s)]
        if not packet.crc_ok:
            self.crc_errors += 1
            target = next((s for s in listening if s.dxl_id == packet.dxl_id), None)
            if target is None or not self._answers(target, packet.instruction):
                return []
            return [self._status(target, Error.CRC)]
        self.last_packet_s = now_s
        self._sample()
        inst, p = packet.instruction, packet.params
        if inst in (
            Instruction.SYNC_READ,
            Instruction.FAST_SYNC_READ,
            Instruction.BULK_READ,
            Instruction.FAST_BULK_READ,
        ):
            return self._group_read(packet, listening, now_s) if packet.dxl_id == BROADCAST_ID else []
        if inst in (Instruction.SYNC_WRITE, Instruction.BULK_WRITE):
            if packet.dxl_id == BROADCAST_ID:
                self._group_write(inst, p, listening, now_s)
            return []
        if packet.dxl_id == BROADCAST_ID:
            if inst == Instruction.FACTORY_RESET and p[:1] == bytes((RESET_ALL,)):
                return []  # never reset everything by broadcast (firmware 42 and up)
            targets = sorted(listening, key=lambda s: s.dxl_id)
        else:
            targets = [s for s in listening if packet.dxl_id in (s.dxl_id, s.secondary_id)]
        replies = []
        for s in targets:
            answer = packet.dxl_id == s.dxl_id or (packet.dxl_id == BROADCAST_ID and inst == Instruction.PING)
            reply = self._execute(s, inst, p, now_s, answer and self._answers(s, inst))
            if reply is not None:
                replies.append(reply)
        return replies

    @staticmethod
    def _answers(servo: Servo, inst: int) -> bool:
        if inst in FAST_READS and servo.firmware < FAST_READ_FIRMWARE:
            return False  # an instruction it does not know: no reply to a broadcast
        level = servo.status_return_level
        return inst == Instruction.PING or level == 2 or (level == 1 and inst in READS + FAST_READS)

    @staticmethod
    def _status(s: Servo, error: Error, data: bytes = b"") -> Reply:
        return Reply(status_packet(s.dxl_id, s.error_byte(error), data), s.return_delay_s)

    def _execute(self, s: Servo, inst: int, p: bytes, now_s: float, answer: bool) -> Reply | None:
        """One servo's share of a unicast or broadcast instruction; its reply if `answer`."""
        data = b""
        if inst == Instruction.PING:
            data, error = s.ping(), Error.NONE
        elif inst == Instruction.READ:
            result = s.read(_word(p, 0), _word(p, 2), now_s) if len(p) == 4 else Error.DATA_LENGTH
            data, error = (result, Error.NONE) if isinstance(result, bytes) else (b"", result)
        elif inst in (Instruction.WRITE, Instruction.REG_WRITE):
            if len(p) < 3:
                error = Error.DATA_LENGTH
            elif inst == Instruction.WRITE:
                error = s.write(_word(p, 0), p[2:], now_s)
            else:
                error = s.reg_write(_word(p, 0), p[2:])
        elif inst == Instruction.ACTION:
            error = s.action(now_s)
        elif inst in (Instruction.FACTORY_RESET, Instruction.REBOOT):
            return self._restart(s, inst, p, now_s, answer)
        elif inst == Instruction.CLEAR:
            error = s.clear(p)
        else:
            error = Error.INSTRUCTION
        return self._maybe(s, error, answer, data)

    def _restart(self, s: Servo, inst: int, p: bytes, now_s: float, answer: bool) -> Reply | None:
        """Reboot or factory reset: the status goes out as the servo was, then it restarts."""
        before = self._status(s, Error.NONE)
        if inst == Instruction.REBOOT:
            s.boot(now_s)
            return before if answer else None
        if len(p) != 1:
            return self._maybe(s, Error.DATA_LENGTH, answer)
        error = s.factory_reset(p[0], now_s)
        if error:
            return self._maybe(s, error, answer)
        return before if answer else None

    def _maybe(self, s: Servo, error: Error, answer: bool, data: bytes = b"") -> Reply | None:
        return self._status(s, error, data) if answer else None

    def _group_read(self, packet: Packet, listening: list[Servo], now_s: float) -> list[Reply]:
        p, inst = packet.params, packet.instruction
        if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
            if len(p) < 5:
                return []
            address, length = _word(p, 0), _word(p, 2)
            asked = [(i, address, length) for i in p[4:]]
        else:
            asked = [(p[k], _word(p, k + 1), _word(p, k + 3)) for k in range(0, len(p) - 4, 5)]
        by_id = {s.dxl_id: s for s in listening if self._answers(s, inst)}
        if inst in FAST_READS:
            return self._fast_read(asked, by_id, now_s)
        replies = []
        for dxl_id, address, length in asked:
            s = by_id.get(dxl_id)
            if s is not None:
                result = s.read(address, length, now_s)
                if isinstance(result, bytes):
                    replies.append(self._status(s, Error.NONE, result))
                else:
                    replies.append(self._status(s, result))
        return replies

    def _fast_read(
        self, asked: list[tuple[int, int, int]], by_id: dict[int, Servo], now_s: float
    ) -> list[Reply]:
        """One packet built by the servos in turn; it stops where a servo does not answer (the
        controller then times out on a short packet, as on a real bus)."""
        parts: list[tuple[int, int, bytes]] = []
        cut = None
        offset = 8  # header, id, length, instruction
        for dxl_id, address, length in asked:
            s = by_id.get(dxl_id)
            if s is None:
                cut = offset if cut is None else cut
                parts.append((dxl_id, 0, bytes(length)))
            else:
                result = s.read(address, length, now_s)
                data = result if isinstance(result, bytes) else bytes(length)
                error = Error.NONE if isinstance(result, bytes) else result
                parts.append((dxl_id, s.error_byte(error), data))
            offset += length + 4
        first = by_id.get(asked[0][0]) if asked else None
        if first is None:
            return []
        packet = fast_status_packet(parts)
        return [Reply(packet if cut is None else packet[:cut], first.return_delay_s)]

    def _group_write(self, inst: int, p: bytes, listening: list[Servo], now_s: float) -> None:
        writes: list[tuple[int, int, bytes]] = []
        if inst == Instruction.SYNC_WRITE and len(p) >= 4:
            address, length = _word(p, 0), _word(p, 2)
            step = length + 1
            writes = [(p[k], address, p[k + 1 : k + step]) for k in range(4, len(p) - length, step)]
        elif inst == Instruction.BULK_WRITE:
            k = 0
            while k + 5 <= len(p):
                length = _word(p, k + 3)
                writes.append((p[k], _word(p, k + 1), p[k + 5 : k + 5 + length]))
                k += 5 + length
        for dxl_id, address, data in writes:
            for s in listening:
                if dxl_id in (s.dxl_id, s.secondary_id):
                    s.write(address, data, now_s)

    # ---- noise and faults -----------------------------------------------------------------
    def corrupt(self, data: bytes) -> bytes:
        """`data` with each byte's one random bit flipped at probability `noise_rate`."""
        if not self.noise_rate or not data:
            return data
        out = bytearray(data)
        for i in range(len(out)):
            if self.rng.random() < self.noise_rate:
                out[i] ^= 1 << self.rng.randrange(8)
        return bytes(out)

    def make_late(self, late_s: float, packets: int) -> None:
        """The next `packets` status packets come `late_s` after their due time."""
        if not 0.0 <= late_s <= 1.0 or packets < 0:
            raise ValueError(f"late: ms (={late_s * 1e3:g}) must be in [0, 1000], packets (={packets}) >= 0")
        self.late_s, self.late_packets = late_s, packets

    def delay_s(self) -> float:
        """Extra delay of the next status packet (and one fewer late ones to come)."""
        if self.late_packets <= 0:
            return 0.0
        self.late_packets -= 1
        return self.late_s

    def place_object(self, dxl_id: int | None, at_rad: float, stiffness_nm_rad: float, closing: int) -> None:
        """An object the joint of servo `dxl_id` meets at `at_rad` (joint angle) when it moves in
        the `closing` sense (+1 or -1), pushing back with `stiffness_nm_rad`."""
        j = self._joint_of(dxl_id)
        if closing not in (1, -1) or not stiffness_nm_rad > 0.0 or not math.isfinite(at_rad):
            raise ValueError(
                f"object: closing (={closing!r}) must be 1 or -1, stiffness_nm_rad (={stiffness_nm_rad!r}) "
                f"> 0, at_rad (={at_rad!r}) finite"
            )
        self.obstacles[j] = Obstacle(j, at_rad, stiffness_nm_rad, closing)

    def remove_object(self, dxl_id: int | None) -> None:
        self.obstacles.pop(self._joint_of(dxl_id), None)

    def _joint_of(self, dxl_id: int | None) -> int:
        for j, s in enumerate(self.servos):
            if s.dxl_id == dxl_id:
                return j
        ids = ", ".join(str(s.dxl_id) for s in self.servos)
        raise ValueError(f"no servo with id {dxl_id!r} (ids: {ids})")

    def inject(self, fault: str, dxl_id: int | None, rate: float, now_s: float) -> None:
        """Inject `fault` (one of `FAULTS`) into servo `dxl_id` (noise: at `rate` per byte)."""
        if fault == "noise":
            if not 0.0 <= rate <= 1.0 or math.isnan(rate):
                raise ValueError(f"noise rate (={rate!r}) must be in [0, 1]")
            self.noise_rate = rate
            return
        if fault == "clear":
            self.noise_rate = 0.0
            self.obstacles.clear()
            for s in self.servos:
                s.held_temperature_c = None
                s.replug(now_s)
            return
        servo = next((s for s in self.servos if s.dxl_id == dxl_id), None)
        if servo is None:
            ids = ", ".join(str(s.dxl_id) for s in self.servos)
            raise ValueError(f"no servo with id {dxl_id!r} (ids: {ids})")
        self.advance_to(now_s)
        if fault == "overload":
            servo.raise_hardware_error(OVERLOAD)
        elif fault == "overheating":
            servo.held_temperature_c = servo.table.get(T.TEMPERATURE_LIMIT) + 5.0
            servo.loop.temperature_c = servo.held_temperature_c
            servo.raise_hardware_error(OVERHEATING)
        elif fault == "unplug":
            servo.unplug()
        elif fault == "replug":
            servo.replug(now_s)
        else:
            raise ValueError(f"unknown fault {fault!r} (faults: {', '.join(FAULTS)})")
