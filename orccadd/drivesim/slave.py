"""A CANopen slave node (CiA 301) over an object dictionary from an EDS/DCF file.

No I/O here: frames come in through `on_frame`, time through `poll`, and frames go out
through the `send` callable given at construction. What it does:

- NMT: boot-up message, PRE-OPERATIONAL / OPERATIONAL / STOPPED, reset node and reset
  communication (object values back to the description's defaults), addressed or broadcast;
- SDO server: expedited and segmented upload and download, abort codes of CiA 301 for a
  missing object or sub-index, a read-only object, a wrong length, a value out of range,
  a toggle error; block transfers are refused (abort "command not valid");
- an expedited download without a size indication (e = 1, s = 0, which CiA 301 allows) is
  taken as the object's own size from the 4 data bytes and logged, naming the object; bytes
  beyond that size that are not zero (nor the sign extension of a signed value) would be lost:
  aborted 0x06070012 (docs/simulators.md, "drivesim where CiA 301 and CiA 402 leave room");
- PDOs from 0x1400/0x1600 (receive) and 0x1800/0x1A00 (transmit), reconfigurable over SDO
  following CiA 301's procedure only (disable the PDO, set the count to 0, write the entries,
  set the count, enable): a mapping write while the PDO is valid, or an entry while the count
  is not 0, is aborted 0x06010000; entries checked (exists 0x06020000, mappable 0x06040041), a
  count beyond the entries or 64 bits 0x06040042; RPDOs with a synchronous transmission type
  are applied at the next SYNC, others at once; TPDOs of type 1-240 go out every n-th SYNC,
  type 0 on SYNC when changed, 254/255 on their event timer;
- heartbeat producer (0x1017) and consumer (0x1016, a lost producer is reported to the owner),
  EMCY (0x1014, default 0x80 + node id) with the error register 0x1001;
- COB-IDs as strict drives keep them (`strict_cob_ids`, on by default): a write that changes the
  identifier (bits 0-29) of a valid COB-ID (bit 31 clear) of a PDO (0x1400-/0x1800- sub 1) or of
  the EMCY (0x1014) is aborted with 0x06090030, as CiA 301 lets the identifier change only while
  bit 31 says "not valid".

The objects, their values and their typed SDO access are `objects.ObjectStore`'s (the EtherCAT
simulator's CoE server serves the same store); this class adds CAN's side and the PDO rules
(`_before_store`, `_after_store`).

Write hooks (`on_write`) let the drive behind the node react to controlword and friends,
whether they arrive by PDO or SDO; checks (`checks`) let it refuse a value before it is stored
(an SDO download is aborted with the check's code, an RPDO's entry left as it was).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import can
from canopen.objectdictionary import ODVariable

from orccadd.drivesim.objects import (
    ABORT_COMMAND,
    ABORT_DEVICE_STATE,
    ABORT_GENERAL,
    ABORT_LENGTH,
    ABORT_NO_OBJECT,
    ABORT_NO_SUBINDEX,
    ABORT_NOT_MAPPABLE,
    ABORT_PDO_LENGTH,
    ABORT_READ_ONLY,
    ABORT_TOGGLE,
    ABORT_TOO_LONG,
    ABORT_UNSUPPORTED_ACCESS,
    ABORT_VALUE_HIGH,
    ABORT_VALUE_LOW,
    ABORT_VALUE_RANGE,
    ABORT_WRITE_ONLY,
    ObjectStore,
    SdoAbortError,
)

__all__ = [
    "ABORT_COMMAND",
    "ABORT_DEVICE_STATE",
    "ABORT_GENERAL",
    "ABORT_LENGTH",
    "ABORT_MAPPING_ORDER",
    "ABORT_NOT_MAPPABLE",
    "ABORT_NO_OBJECT",
    "ABORT_NO_SUBINDEX",
    "ABORT_PDO_LENGTH",
    "ABORT_READ_ONLY",
    "ABORT_TOGGLE",
    "ABORT_TOO_LONG",
    "ABORT_UNSUPPORTED_ACCESS",
    "ABORT_VALUE_HIGH",
    "ABORT_VALUE_LOW",
    "ABORT_VALUE_RANGE",
    "ABORT_WRITE_ONLY",
    "Nmt",
    "Pdo",
    "SdoAbortError",
    "SlaveNode",
]

# a mapping written out of CiA 301's order (the PDO still valid, or an entry while the count is not
# 0): CiA 301 names no code for it; CANopenNode and Copley's drives answer "unsupported access"
ABORT_MAPPING_ORDER = ABORT_UNSUPPORTED_ACCESS

COB_NMT, COB_SYNC = 0x000, 0x080
COB_INVALID = 1 << 31  # bit 31 of a COB-ID (PDO, EMCY): 1 = not valid
COB_IDENTIFIER = 0x3FFFFFFF  # bits 0-29: what may change only while not valid


class Nmt(IntEnum):
    """NMT states with their heartbeat codes."""

    INITIALISING = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


@dataclass
class Pdo:
    """One PDO as configured now: its COB-ID, transmission type and mapped entries."""

    comm: int  # 0x1400+k or 0x1800+k
    mapping: int  # 0x1600+k or 0x1A00+k
    transmit: bool
    cob_id: int = 0
    valid: bool = False
    trans_type: int = 255
    event_timer_ms: int = 0
    entries: list[tuple[int, int, int]] = field(default_factory=list)  # (index, sub, bits)
    sync_count: int = 0
    pending: bytes | None = None  # a synchronous RPDO waiting for the next SYNC
    last_data: bytes = b""
    next_event_s: float = 0.0


@dataclass
class _Segmented:
    index: int
    sub: int
    upload: bool
    data: bytearray
    toggle: int = 0
    size: int | None = None


class SlaveNode(ObjectStore):
    """A CANopen slave over an `ObjectStore`: its values, `checks` and `on_write` hooks are the
    store's; frames in through `on_frame`, out through `send`."""

    def __init__(
        self, node_id: int, eds: str, send: Callable[[can.Message], None], strict_cob_ids: bool = True
    ) -> None:
        super().__init__(eds, node_id)
        self.strict_cob_ids = strict_cob_ids
        self.now_s = 0.0  # the time of the frame or poll being handled
        self.eds = eds
        self.send = send
        self.on_heartbeat_lost: Callable[[int], None] = lambda producer: None
        self.on_reset_node: Callable[[], None] = lambda: None  # the application resets too
        self.nmt = Nmt.INITIALISING
        self.silent = False  # fault injection: the node sends nothing at all
        self.heartbeat_silent = False  # fault injection: no heartbeat
        self.rpdos: dict[int, Pdo] = {}
        self.pdo_generation = 0  # bumped whenever a PDO's parameters are (re)loaded
        self.tpdos: dict[int, Pdo] = {}
        self._seg: _Segmented | None = None
        self._next_heartbeat_s = 0.0
        self._consumers: dict[int, tuple[float, float]] = {}  # producer -> (timeout_s, last_seen_s)
        self._lost: set[int] = set()

    # ---- object values -------------------------------------------------------------------
    def defaults(self, comm_only: bool) -> None:
        """Values back to the description's defaults, and the PDOs rebuilt from them."""
        super().defaults(comm_only)
        self._build_pdos()

    # ---- NMT -------------------------------------------------------------------------------
    def boot(self, now_s: float) -> None:
        """Power on (or reset node): defaults, boot-up message, PRE-OPERATIONAL."""
        self._reset(now_s, comm_only=False)

    def _reset(self, now_s: float, comm_only: bool) -> None:
        self.defaults(comm_only)
        if not comm_only:  # the application restarts too: its own values, before the boot-up
            self.on_reset_node()
        self._seg = None
        self.nmt = Nmt.PRE_OPERATIONAL
        self._lost.clear()
        self._configure_consumers(now_s)
        self._emit(0x700 + self.node_id, b"\x00")  # boot-up
        self._next_heartbeat_s = now_s

    def _nmt_command(self, cs: int, now_s: float) -> None:
        if cs == 0x01:
            self.nmt = Nmt.OPERATIONAL
        elif cs == 0x02:
            self.nmt = Nmt.STOPPED
        elif cs == 0x80:
            self.nmt = Nmt.PRE_OPERATIONAL
        elif cs == 0x81:
            self._reset(now_s, comm_only=False)
        elif cs == 0x82:
            self._reset(now_s, comm_only=True)

    # ---- frames in -----------------------------------------------------------------------
    def on_frame(self, msg: can.Message, now_s: float) -> None:
        self.now_s = now_s
        cob = msg.arbitration_id
        data = bytes(msg.data)
        if msg.is_extended_id or msg.is_remote_frame:
            return
        if cob == COB_NMT:
            if len(data) == 2 and data[1] in (0, self.node_id):
                self._nmt_command(data[0], now_s)
            return
        if self.nmt is Nmt.STOPPED:
            if 0x700 <= cob <= 0x77F:
                self._heartbeat_seen(cob - 0x700, now_s)
            return
        if cob == 0x600 + self.node_id:
            if len(data) == 8:
                self._sdo(data)
            return
        if 0x700 <= cob <= 0x77F:
            self._heartbeat_seen(cob - 0x700, now_s)
            return
        if self.nmt is not Nmt.OPERATIONAL:
            return
        for pdo in self.rpdos.values():
            if pdo.valid and pdo.cob_id == cob:
                if pdo.trans_type <= 240:
                    pdo.pending = data
                else:
                    self._apply_rpdo(pdo, data)
                return

    def on_sync(self, now_s: float) -> None:
        """A SYNC arrived: apply synchronous RPDOs (the owner then runs its cycle and calls
        `transmit_sync_pdos`)."""
        if self.nmt is not Nmt.OPERATIONAL:
            return
        for pdo in self.rpdos.values():
            if pdo.pending is not None:
                data, pdo.pending = pdo.pending, None
                self._apply_rpdo(pdo, data)

    def transmit_sync_pdos(self) -> None:
        if self.nmt is not Nmt.OPERATIONAL:
            return
        for pdo in self.tpdos.values():
            if not pdo.valid or pdo.trans_type > 240:
                continue
            if pdo.trans_type == 0:
                data = self._pack(pdo)
                if data != pdo.last_data:
                    self._send_pdo(pdo, data)
                continue
            pdo.sync_count += 1
            if pdo.sync_count >= pdo.trans_type:
                pdo.sync_count = 0
                self._send_pdo(pdo, self._pack(pdo))

    def poll(self, now_s: float) -> None:
        """Timers: heartbeat producer, event-timer TPDOs, heartbeat consumers."""
        self.now_s = now_s
        if self.nmt is Nmt.INITIALISING:
            return
        period_ms = int(self.values.get((0x1017, 0), 0) or 0)
        if period_ms and now_s >= self._next_heartbeat_s:
            # never sooner than 0x1017 after the last one, however late this one is
            self._next_heartbeat_s = now_s + period_ms / 1000
            if not self.heartbeat_silent:
                self._emit(0x700 + self.node_id, bytes([self.nmt]))
        if self.nmt is Nmt.OPERATIONAL:
            for pdo in self.tpdos.values():
                if pdo.valid and pdo.trans_type >= 254 and pdo.event_timer_ms and now_s >= pdo.next_event_s:
                    pdo.next_event_s = now_s + pdo.event_timer_ms / 1000
                    self._send_pdo(pdo, self._pack(pdo))
        for producer, (timeout_s, last_s) in self._consumers.items():
            if producer not in self._lost and last_s and now_s - last_s > timeout_s:
                self._lost.add(producer)
                self.on_heartbeat_lost(producer)

    def emergency(self, code: int, register: int, manufacturer: bytes = b"") -> None:
        """Send an EMCY (code 0 = error reset / no error) and store the error register."""
        if self.has(0x1001):
            self.values[(0x1001, 0)] = register
        cob = int(self.values.get((0x1014, 0), 0x80 + self.node_id)) & 0x7FF
        payload = struct.pack("<HB", code, register) + manufacturer[:5].ljust(5, b"\x00")
        self._emit(cob, payload)

    # ---- heartbeat consumer ----------------------------------------------------------------
    def _configure_consumers(self, now_s: float) -> None:
        self._consumers = {}
        n = int(self.values.get((0x1016, 0), 0) or 0)
        for sub in range(1, n + 1):
            entry = int(self.values.get((0x1016, sub), 0) or 0)
            producer, time_ms = entry >> 16 & 0x7F, entry & 0xFFFF
            if producer and time_ms:
                self._consumers[producer] = (time_ms / 1000, 0.0)  # armed by the first heartbeat

    def _heartbeat_seen(self, producer: int, now_s: float) -> None:
        if producer in self._consumers:
            timeout_s, _ = self._consumers[producer]
            self._consumers[producer] = (timeout_s, now_s)
            self._lost.discard(producer)

    # ---- PDOs --------------------------------------------------------------------------------
    def _build_pdos(self) -> None:
        self.rpdos = self._pdos(0x1400, 0x1600, transmit=False)
        self.tpdos = self._pdos(0x1800, 0x1A00, transmit=True)

    def _pdos(self, comm0: int, map0: int, transmit: bool) -> dict[int, Pdo]:
        out = {}
        for k in range(512):
            if (comm0 + k, 1) not in self.values or (map0 + k, 0) not in self.values:
                continue
            pdo = Pdo(comm0 + k, map0 + k, transmit)
            self._load_pdo(pdo)
            out[comm0 + k] = pdo
        return out

    def unicast_cobs(self) -> frozenset[int]:
        """The COB-IDs only this node consumes: its SDO requests and its valid RPDOs (NMT, SYNC
        and heartbeats concern every node). Changes when `pdo_generation` does."""
        return frozenset({0x600 + self.node_id, *(p.cob_id for p in self.rpdos.values() if p.valid)})

    def _load_pdo(self, pdo: Pdo) -> None:
        self.pdo_generation += 1
        cob = int(self.values[(pdo.comm, 1)])
        pdo.cob_id = cob & 0x7FF
        pdo.valid = not cob & COB_INVALID and pdo.cob_id != 0
        pdo.trans_type = int(self.values.get((pdo.comm, 2), 255))
        pdo.event_timer_ms = int(self.values.get((pdo.comm, 5), 0) or 0) if pdo.transmit else 0
        n = int(self.values[(pdo.mapping, 0)])
        pdo.entries = []
        for sub in range(1, n + 1):
            e = int(self.values.get((pdo.mapping, sub), 0))
            pdo.entries.append((e >> 16, e >> 8 & 0xFF, e & 0xFF))
        pdo.sync_count = 0
        pdo.pending = None
        pdo.last_data = b""

    def _pack(self, pdo: Pdo) -> bytes:
        parts = []
        for index, sub, _bits in pdo.entries:
            parts.append(self.vars[(index, sub)].encode_raw(self.values[(index, sub)]))
        return b"".join(parts)

    def _apply_rpdo(self, pdo: Pdo, data: bytes) -> None:
        offset = 0
        for index, sub, bits in pdo.entries:
            n = bits // 8
            chunk = data[offset : offset + n]
            offset += n
            if len(chunk) < n:
                return  # a short frame: the drive ignores it (real drives raise an EMCY 0x8210)
            if (index, sub) not in self.vars:  # dummy mapping
                continue
            value = self.vars[(index, sub)].decode_raw(chunk)
            check = self.checks.get((index, sub))
            if check is not None:
                try:
                    check(value)
                except SdoAbortError:
                    continue  # refused: the object keeps its value (no one to abort to)
            self.values[(index, sub)] = value
            hook = self.on_write.get((index, sub))
            if hook is not None:
                hook(value)

    def _send_pdo(self, pdo: Pdo, data: bytes) -> None:
        pdo.last_data = data
        self._emit(pdo.cob_id, data)

    def _check_mapping_write(self, index: int, sub: int, value: int) -> None:
        """CiA 301's procedure: (1) the PDO not valid, (2) the count 0, (3) the entries, each one
        existing (0x06020000) and mappable (0x06040041), (4) the count, within the entries there
        are and 64 bits (0x06040042). A write out of that order: 0x06010000."""
        pdo = self._pdo_by_mapping(index)
        if pdo is None:
            return
        if pdo.valid:
            raise SdoAbortError(ABORT_MAPPING_ORDER)  # step 1 first: bit 31 of the COB-ID set
        if sub != 0:
            if int(self.values.get((index, 0), 0)) != 0:
                raise SdoAbortError(ABORT_MAPPING_ORDER)  # step 2 first: the count at 0
            self._check_entry(value, pdo.transmit)
            return
        if value > sum(1 for i, s in self.vars if i == index and s > 0):
            raise SdoAbortError(ABORT_PDO_LENGTH)
        bits = sum(
            self._check_entry(int(self.values.get((index, s), 0)), pdo.transmit) for s in range(1, value + 1)
        )
        if bits > 64:
            raise SdoAbortError(ABORT_PDO_LENGTH)

    def _check_cob_id_write(self, key: tuple[int, int], value: int) -> None:
        """Strict drives: a valid COB-ID keeps its identifier (CiA 301)."""
        is_cob_id = key == (0x1014, 0) or (key[1] == 1 and self._pdo_by_comm(key[0]) is not None)
        if not self.strict_cob_ids or not is_cob_id:
            return
        current = int(self.values.get(key, 0) or 0)
        valid = not current & COB_INVALID and current & COB_IDENTIFIER
        if valid and (current ^ value) & COB_IDENTIFIER:
            raise SdoAbortError(ABORT_VALUE_RANGE)

    def _check_entry(self, entry: int, transmit: bool) -> int:
        index, sub, bits = entry >> 16, entry >> 8 & 0xFF, entry & 0xFF
        if 1 <= index <= 7:  # dummy entries (data types) for unused bytes
            return bits
        var = self.vars.get((index, sub))
        if var is None:
            raise SdoAbortError(ABORT_NO_OBJECT)
        access_ok = var.readable if transmit else var.writable
        if not var.pdo_mappable or not access_ok or bits != len(var) or bits % 8:
            raise SdoAbortError(ABORT_NOT_MAPPABLE)
        return bits

    def _pdo_by_mapping(self, index: int) -> Pdo | None:
        for pdo in (*self.rpdos.values(), *self.tpdos.values()):
            if pdo.mapping == index:
                return pdo
        return None

    def _pdo_by_comm(self, index: int) -> Pdo | None:
        return self.rpdos.get(index) or self.tpdos.get(index)

    # ---- SDO server ----------------------------------------------------------------------------
    def _sdo(self, req: bytes) -> None:
        cmd = req[0]
        ccs = cmd >> 5
        try:
            if ccs == 4:  # abort from the client
                self._seg = None
                return
            if ccs in (0, 3):
                self._segment(req)
                return
            index, sub = struct.unpack_from("<HB", req, 1)
            if ccs == 1:
                self._download_initiate(cmd, index, sub, req)
            elif ccs == 2:
                self._upload_initiate(index, sub)
            else:
                raise SdoAbortError(ABORT_COMMAND)  # block transfers are not offered
        except SdoAbortError as e:
            self._abort(ccs, req, e.code)
        except (ValueError, TypeError, struct.error):  # a value the description cannot encode
            self._abort(ccs, req, ABORT_GENERAL)

    def _abort(self, ccs: int, req: bytes, code: int) -> None:
        self._seg = None
        idx, sb = struct.unpack_from("<HB", req, 1) if ccs not in (0, 3) else (0, 0)
        self._sdo_reply(struct.pack("<BHBI", 0x80, idx, sb, code))

    def _upload_initiate(self, index: int, sub: int) -> None:
        data = self.read(index, sub)
        if len(data) <= 4:
            n = 4 - len(data)
            self._sdo_reply(struct.pack("<BHB", 0x43 | n << 2, index, sub) + data.ljust(4, b"\x00"))
        else:
            self._seg = _Segmented(index, sub, upload=True, data=bytearray(data))
            self._sdo_reply(struct.pack("<BHBI", 0x41, index, sub, len(data)))

    def _download_initiate(self, cmd: int, index: int, sub: int, req: bytes) -> None:
        var = self.var(index, sub)
        if not var.writable:
            raise SdoAbortError(ABORT_READ_ONLY)
        expedited, sized = bool(cmd & 0x02), bool(cmd & 0x01)
        if expedited:
            data = bytes(req[4 : 8 - (cmd >> 2 & 0x3)]) if sized else self.unsized(var, bytes(req[4:8]))
            self._store(var, data)
            self._sdo_reply(struct.pack("<BHB", 0x60, index, sub) + b"\x00" * 4)
        else:
            total: int | None = struct.unpack_from("<I", req, 4)[0] if sized else None
            self._seg = _Segmented(index, sub, upload=False, data=bytearray(), size=total)
            self._sdo_reply(struct.pack("<BHB", 0x60, index, sub) + b"\x00" * 4)

    def _segment(self, req: bytes) -> None:
        seg = self._seg
        cmd = req[0]
        if seg is None or seg.upload != (cmd >> 5 == 3):
            raise SdoAbortError(ABORT_COMMAND)
        toggle = cmd >> 4 & 1
        if toggle != seg.toggle:
            raise SdoAbortError(ABORT_TOGGLE)
        seg.toggle ^= 1
        if seg.upload:
            chunk, seg.data = seg.data[:7], seg.data[7:]
            last = not seg.data
            n = 7 - len(chunk)
            self._sdo_reply(bytes([toggle << 4 | n << 1 | int(last)]) + bytes(chunk).ljust(7, b"\x00"))
            if last:
                self._seg = None
            return
        n = 7 - (cmd >> 1 & 0x7)
        seg.data += req[1 : 1 + n]
        if cmd & 0x01:  # last segment
            self._seg = None
            if seg.size is not None and seg.size != len(seg.data):
                raise SdoAbortError(ABORT_LENGTH)
            self.write(seg.index, seg.sub, bytes(seg.data))
        self._sdo_reply(bytes([0x20 | toggle << 4]) + b"\x00" * 7)

    def _before_store(self, var: ODVariable, value: Any) -> None:
        """The PDO rules, before the description's limits: CiA 301 names their codes."""
        if isinstance(value, int):
            self._check_mapping_write(var.index, var.subindex, value)
            self._check_cob_id_write((var.index, var.subindex), value)

    def _after_store(self, var: ODVariable, value: Any) -> None:
        pdo = self._pdo_by_comm(var.index) or self._pdo_by_mapping(var.index)
        if pdo is not None:  # a PDO's parameters changed: it follows at once
            self._load_pdo(pdo)
        if var.index == 0x1016:
            self._configure_consumers(0.0)

    def _sdo_reply(self, payload: bytes) -> None:
        self._emit(0x580 + self.node_id, payload)

    def _emit(self, cob: int, data: bytes) -> None:
        if not self.silent:
            self.send(can.Message(arbitration_id=cob, data=data, is_extended_id=False))
