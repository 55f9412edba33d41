"""The servos on one port: the bus transactions the backend makes, through the stock SDK.

`dynamixel_sdk.PacketHandler` builds, sends and checks every packet (CRC, stuffing, lengths);
`GroupSyncRead` and `GroupSyncWrite` build the group instructions. Two things are ours:

- the port under them (`port.BlockingPort`: blocking reads, deadlines from the wire time);
- the status packet of the cyclic Fast Sync Read is received with the SDK's `rxPacket` and cut
  into servos here, because `GroupSyncRead` drops each servo's error byte (its alert bit says a
  hardware error is latched: the backend then reads Hardware Error Status(70) of that servo)
  and a short packet (it stops where a servo did not answer) names the missing servo.

Every method is one transaction, or a few, under `lock`: the control thread's ticks and a
lifecycle call from another thread (reset, clear_stop) never interleave on the wire. The cyclic
pair (`read_cycle`, `write_goals`) allocates only the SDK's packet lists.

A port whose device is gone (`BlockingPort.lost`: the adapter unplugged) makes the cyclic pair
answer at once (READ_LOST, a failed write) without touching it, and every other transaction a
`ChainError` naming the port; `reopen` opens the device path again (the backend's reset).
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager

from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    COMM_TX_FAIL,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
)

from orccadd.drivers.dynamixel import table as T
from orccadd.drivers.dynamixel.errors import comm_text, packet_error_text
from orccadd.drivers.dynamixel.models import model_name
from orccadd.drivers.dynamixel.port import BlockingPort, open_port
from orccadd.drivers.dynamixel.settings import DynamixelSettings
from orccadd.errors import ResourceError

HEADER = (0xFF, 0xFF, 0xFD)
STATUS = 0x55
_PART = struct.Struct("<BBhii")  # error, id, Present Current (or Load), Velocity, Position

LIFECYCLE_TIMEOUT_S = 0.05  # beyond the wire time, for a transaction outside the cycle

# what the last cyclic read did (READ_LOST: the port is gone, `ServoChain.lost` says why)
READ_OK, READ_TIMEOUT, READ_CORRUPT, READ_LOST = 0, 1, 2, 3


class ChainError(ResourceError):
    """A transaction with a servo failed: the message names the servo and what happened."""


class ServoChain:
    """The chain of `settings.servos` (index j = joint j) on `settings.port`."""

    def __init__(self, settings: DynamixelSettings, joint_names: Sequence[str]) -> None:
        self.settings = settings
        self.ids = [s.id for s in settings.servos]
        self.labels = [
            f"servo {s.id} ({joint}, {s.model})"
            for s, joint in zip(settings.servos, joint_names, strict=True)
        ]
        self.lock = threading.Lock()
        # the cyclic read by Fast Sync Read (one status packet), else Sync Read (one per servo):
        # the config's choice, turned off at configure where a servo's firmware lacks it
        self.fast = settings.fast_sync_read
        self.ph = PacketHandler(2.0)
        self.port: BlockingPort | None = None
        n = len(self.ids)
        # the cyclic read's values, raw servo units, per joint (kept from the last good read)
        self.present_current = [0] * n
        self.present_velocity = [0] * n
        self.present_position = [0] * n
        self.error_byte = [0] * n
        self.active = [True] * n  # in the cyclic read and write (False: lost, or rebooting)
        self._order: list[int] = list(range(n))  # joints in the cyclic read, in bus order
        self._reader: GroupSyncRead | None = None
        self._writers: dict[T.Item, GroupSyncWrite] = {}
        # counters
        self.reads = 0
        self.timeouts = 0
        self.timeouts_by_servo = [0] * n  # timeouts that found this joint's part missing
        self.late_bytes_dropped = 0  # of replies that came after their deadline
        self.crc_errors = 0
        self.in_a_row = 0  # failed cyclic reads since the last good one
        self.cut_at = -1  # joint whose part was missing in the last failed read (-1: none/unknown)
        self.last_result = READ_OK

    # ---- the port ---------------------------------------------------------------------------
    def open(self, latency_s: float = 0.0) -> None:
        s = self.settings
        self.port = open_port(s.port, s.baud_rate, s.read_timeout_s, latency_s)
        self._rebuild()

    def close(self) -> None:
        with self.lock:
            if self.port is not None and self.port.is_open:
                self.port.closePort()

    def reopen(self, latency_s: float = 0.0) -> None:
        """After the port was lost: the old one closed, the device path opened again (a
        `ResourceError` naming it while it is still absent: the old port stays, lost), the
        group objects rebuilt for the joints active. Not for a tick."""
        s = self.settings
        with self.lock:
            if self.port is not None and self.port.is_open:
                self.port.closePort()
            self.port = open_port(s.port, s.baud_rate, s.read_timeout_s, latency_s)
            self._rebuild()

    @property
    def lost(self) -> str:
        """Why the port is gone, in words ("" while it works, or before it was opened)."""
        port = self.port
        return port.lost if port is not None else ""

    def _p(self) -> BlockingPort:
        if self.port is None:
            raise ResourceError(f"the DYNAMIXEL port {self.settings.port} is not open")
        return self.port

    def _live(self) -> BlockingPort:
        """The port for a transaction (under the lock): a `ChainError` naming it if it is gone."""
        port = self._p()
        if port.lost:
            raise ChainError(f"the DYNAMIXEL port {self.settings.port} is gone ({port.lost})")
        return port

    def _rebuild(self) -> None:
        """The group objects for the joints now active (under the lock or before any tick)."""
        port = self._p()
        self._order = [j for j in range(len(self.ids)) if self.active[j]]
        reader = GroupSyncRead(port, self.ph, T.CYCLIC_START, T.CYCLIC_LENGTH)
        for j in self._order:
            reader.addParam(self.ids[j])
        self._reader = reader
        self._writers = {}

    def set_active(self, j: int, active: bool) -> None:
        """Take joint j's servo in or out of the cyclic read and write."""
        with self.lock:
            if self.active[j] != active:
                self.active[j] = active
                self._rebuild()

    # ---- single transactions (lifecycle; each raises ChainError) -----------------------------
    @contextmanager
    def _once(self) -> Iterator[BlockingPort]:
        """The lock and a patient port: a servo's first answer after a while may be slow."""
        with self.lock:
            port = self._live()
            with port.patient(LIFECYCLE_TIMEOUT_S):
                yield port

    def _fail(self, j: int, what: str, result: int, error: int = 0) -> ChainError:
        why = comm_text(result) if result != COMM_SUCCESS else packet_error_text(error)
        return ChainError(f"{self.labels[j]}: {what}: {why}")

    @contextmanager
    def _cyclic(self) -> Iterator[BlockingPort]:
        with self.lock:
            yield self._live()

    def ping(self, j: int) -> int:
        """The model number servo j answers with."""
        with self._once() as port:
            number, result, _ = self.ph.ping(port, self.ids[j])
        if result != COMM_SUCCESS:
            s = self.settings
            raise ChainError(
                f"{self.labels[j]} does not answer a ping on {s.port} at {s.baud_rate} bit/s "
                f"({comm_text(result)}): check its ID, its Baud Rate(8) and its power"
            )
        return int(number)

    def check_model(self, j: int, expected_number: int) -> None:
        number = self.ping(j)
        if number != expected_number:
            raise ChainError(
                f"{self.labels[j]}: the servo with ID {self.ids[j]} is a {model_name(number)}, "
                f"the config says {model_name(expected_number)}"
            )

    def read_bytes(self, j: int, address: int, length: int, patient: bool = True) -> bytes:
        """`length` bytes of servo j's table from `address`. `patient=False` in a tick: the
        cycle's timeout, not a lifecycle step's."""
        with self._once() if patient else self._cyclic() as port:
            data, result, error = self.ph.readTxRx(port, self.ids[j], address, length)
        if result != COMM_SUCCESS or error & 0x7F:
            raise self._fail(j, f"read of {length} bytes at {address}", result, error)
        return bytes(data)

    def read(self, j: int, item: T.Item, patient: bool = True) -> int:
        return item.decode(self.read_bytes(j, item.address, item.size, patient))

    def write(self, j: int, item: T.Item, value: int) -> None:
        with self._once() as port:
            result, error = self.ph.writeTxRx(port, self.ids[j], item.address, item.size, item.encode(value))
        if result != COMM_SUCCESS or error & 0x7F:
            raise self._fail(j, f"write of {item} = {value}", result, error)

    def reboot(self, j: int) -> None:
        """Send Reboot to servo j (it answers, then restarts: silent for a while)."""
        with self._once() as port:
            result, error = self.ph.reboot(port, self.ids[j])
        if result != COMM_SUCCESS:
            raise self._fail(j, "reboot", result, error)

    def wait_answering(self, j: int, timeout_s: float) -> None:
        """Ping servo j until it answers (after a reboot), the lock free between pings."""
        end = time.monotonic() + timeout_s
        while True:
            with self._cyclic() as port:  # a silent servo: the ticks wait no longer than a cycle's
                _, result, _ = self.ph.ping(port, self.ids[j])
            if result == COMM_SUCCESS:
                return
            if time.monotonic() > end:
                raise ChainError(f"{self.labels[j]}: no answer within {timeout_s:g} s of its reboot")
            time.sleep(0.01)

    def sync_write(self, item: T.Item, values: Mapping[int, int]) -> None:
        """One Sync Write of `item` to the joints in `values` (no status packet comes back)."""
        with self.lock:
            self._sync_write(item, values)

    def _sync_write(self, item: T.Item, values: Mapping[int, int]) -> int:
        group = GroupSyncWrite(self._live(), self.ph, item.address, item.size)
        for j, v in values.items():
            group.addParam(self.ids[j], item.encode(v))
        return int(group.txPacket())

    def sync_read(self, item: T.Item) -> dict[int, int]:
        """`item` of every active servo in one (fast) sync read, by joint."""
        with self._once() as port:
            group = GroupSyncRead(port, self.ph, item.address, item.size)
            for j in self._order:
                group.addParam(self.ids[j])
            result = group.fastSyncRead() if self.fast else group.txRxPacket()
            if result != COMM_SUCCESS:
                raise ChainError(f"sync read of {item}: {comm_text(result)}")
            values = {j: group.getData(self.ids[j], item.address, item.size) for j in self._order}
        bits = 8 * item.size
        if item.signed:
            return {j: v - (1 << bits) if v >= 1 << (bits - 1) else v for j, v in values.items()}
        return values

    def burst(self, writes: Sequence[tuple[T.Item, Mapping[int, int]]]) -> None:
        """Several Sync Writes back to back, the lock held across them (a mode switch)."""
        with self.lock:
            for item, values in writes:
                result = self._sync_write(item, values)
                if result != COMM_SUCCESS:
                    raise ChainError(f"sync write of {item}: {comm_text(result)}")

    # ---- the cycle --------------------------------------------------------------------------
    def read_cycle(self) -> int:
        """One (fast) sync read of the active servos' Present Current/Load, Velocity and
        Position (tick-safe). READ_OK with the values in `present_*` and `error_byte`; otherwise
        READ_TIMEOUT (no or a short reply: `cut_at` names the first servo missing),
        READ_CORRUPT (a damaged reply), or READ_LOST (the port is gone: `lost` says why; nothing
        sent once it is), the values kept from the last good read."""
        with self.lock:
            port = self.port
            if port is None or port.lost:
                self.last_result = READ_LOST
                return READ_LOST
            result = self._fast_read() if self.fast else self._plain_read()
            if port.lost:  # found gone in this transaction
                self.last_result = READ_LOST
                return READ_LOST
        self.reads += 1
        self.last_result = result
        if result == READ_OK:
            self.in_a_row = 0
        else:
            self.in_a_row += 1
            if result == READ_TIMEOUT:
                self.timeouts += 1
                if self.cut_at >= 0:
                    self.timeouts_by_servo[self.cut_at] += 1
                with self.lock:  # its late end must not be read as the next cycle's reply
                    self.late_bytes_dropped += port.drop_late_reply()
                if port.lost:
                    self.last_result = READ_LOST
                    return READ_LOST
            else:
                self.crc_errors += 1
        return result

    def cycle_deadline_s(self) -> float:
        """How long the cyclic read waits for its reply (for the last servo's, with plain sync
        reads): the request's and the reply's wire time, the adapter's latency, `read_timeout_s`."""
        port, n = self._p(), len(self._order)
        request = 14 + n  # header, id, length, instruction, address, size, the ids, CRC
        if self.fast:
            return port.deadline_s(request, 8 + n * (T.CYCLIC_LENGTH + 4))
        return port.deadline_s(request, 11 + T.CYCLIC_LENGTH)

    def _fast_read(self) -> int:
        reader, order = self._reader, self._order
        if reader is None or not order:
            return READ_OK
        if reader.fastSyncReadTxPacket() != COMM_SUCCESS:
            self.cut_at = -1
            return READ_TIMEOUT
        rx, result = self.ph.rxPacket(self._p(), True)
        n, part = len(order), T.CYCLIC_LENGTH + 4
        expected = 8 + n * part
        if result == COMM_SUCCESS and len(rx) == expected:
            raw = bytes(rx)
            ids = self.ids
            for k, j in enumerate(order):
                err, dxl_id, cur, vel, pos = _PART.unpack_from(raw, 8 + k * part)
                if dxl_id != ids[j]:
                    self.cut_at = -1
                    return READ_CORRUPT
                self.error_byte[j] = err
                self.present_current[j] = cur
                self.present_velocity[j] = vel
                self.present_position[j] = pos
            return READ_OK
        got = len(rx)
        if got < expected and (got == 0 or (got >= 8 and tuple(rx[:3]) == HEADER and rx[7] == STATUS)):
            self.cut_at = order[max(0, got - 8) // part]  # the first servo whose part is missing
            return READ_TIMEOUT
        self.cut_at = -1
        return READ_CORRUPT if result == COMM_RX_CORRUPT and got >= expected else READ_TIMEOUT

    def _plain_read(self) -> int:
        reader, order = self._reader, self._order
        if reader is None or not order:
            return READ_OK
        if reader.txPacket() != COMM_SUCCESS:
            self.cut_at = -1
            return READ_TIMEOUT
        port, length = self._p(), T.CYCLIC_LENGTH
        for j in order:
            data, result, err = self.ph.readRx(port, self.ids[j], length)
            if result != COMM_SUCCESS:
                self.cut_at = j
                return READ_TIMEOUT if result == COMM_RX_TIMEOUT else READ_CORRUPT
            cur, vel, pos = struct.unpack_from("<hii", bytes(data))
            self.error_byte[j] = err
            self.present_current[j] = cur
            self.present_velocity[j] = vel
            self.present_position[j] = pos
        return READ_OK

    def write_goals(self, item: T.Item, values: Sequence[int]) -> int:
        """One Sync Write of `item` to every active servo, `values` per joint (tick-safe).
        The SDK's result (COMM_SUCCESS, or the port failed; COMM_TX_FAIL at once on a lost one)."""
        with self.lock:
            port = self.port
            if port is None or port.lost:
                return int(COMM_TX_FAIL)
            group = self._writers.get(item)
            if group is None:
                group = self._writers[item] = GroupSyncWrite(port, self.ph, item.address, item.size)
            ids, size, signed = self.ids, item.size, item.signed
            for j in self._order:
                data = list(values[j].to_bytes(size, "little", signed=signed))
                if not group.changeParam(ids[j], data):
                    group.addParam(ids[j], data)
            return int(group.txPacket())
